# Arboretum: two commands from a fresh Debian 12 machine, as root: `make demo` and `make test`.
# Each target installs what it needs first and is quick the second time (stamp files in .venv/).

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
APT_PACKAGES := libusb-1.0-0 libegl1 libgl1 libgles2 libglx-mesa0 libegl-mesa0 xvfb xauth
EXTRAS := server,client,export,photos,vr,dev
export OMP_WAIT_POLICY := PASSIVE
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: all install demo test test-all bench lint docs clean

all: test

# System packages, only when one is missing (dpkg-query is fast; apt-get update only when needed).
$(VENV)/.apt:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if ! $(PYTHON) -c 'import venv, ensurepip' 2>/dev/null; then missing="$$missing python3 python3-venv"; fi; \
	if [ -n "$$missing" ]; then \
	  echo "apt: installing$$missing"; \
	  if [ "$$(id -u)" != 0 ]; then echo "apt packages missing ($$missing); run as root or install them"; exit 1; fi; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	fi
	@mkdir -p $(VENV) && touch $@

$(VENV)/.installed: pyproject.toml Makefile $(VENV)/.apt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e ".[$(EXTRAS)]"
	@touch $@

# The Khronos glTF validator (npm), used by the export tests. Node from Debian when missing.
VALIDATOR := tools/gltf-validator
$(VALIDATOR)/node_modules/.installed: $(VALIDATOR)/package-lock.json $(VENV)/.apt
	@command -v npm >/dev/null || { echo "apt: installing nodejs npm"; apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nodejs npm; }
	npm ci --silent --no-audit --no-fund --prefix $(VALIDATOR)
	@touch $@

install: $(VENV)/.installed $(VALIDATOR)/node_modules/.installed

demo: install
	$(BIN)/arboretum demo --out out

lint: install
	$(BIN)/ruff check library server client tests bench examples
	$(BIN)/lint-imports

test: install
	$(BIN)/ruff check library server client tests bench examples
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q -p no:cacheprovider

# Everything, including suites marked slow.
test-all: install
	$(BIN)/python -m pytest -q -p no:cacheprovider -m ""

bench: install
	$(BIN)/python -m bench
	$(BIN)/python -m bench.report --update

clean:
	rm -rf $(VENV) out .pytest_cache
