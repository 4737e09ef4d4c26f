"""Shared fixtures: a fixed seed, strict floating point, the bundled scans."""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.assets import assets_dir

REPO = Path(__file__).resolve().parents[1]
SHARED_SCANS = REPO.parent / "shared" / "data" / "scans"

# Run under nohup or '&' in a script, the tests inherit SIGINT ignored, and so does every command they
# start (an ignored signal stays ignored across exec): the Ctrl-C tests then see their command finish
# or hang instead of stopping (3 failed so). A handler is reset to the default on exec, so children
# start with Ctrl-C working again.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _strict_numpy():
    old = np.seterr(all="raise", under="ignore")
    yield
    np.seterr(**old)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def scans_dir() -> Path:
    """Bundled copies of the real scans (assets/scans), each with its licence."""
    return assets_dir() / "scans"


@pytest.fixture
def folders(tmp_path):
    """(library, state) folders of a service under test (``factories.service_folders``)."""
    from factories import service_folders

    return service_folders(tmp_path)


@pytest.fixture(scope="session")
def toy_tree():
    """The ground tests' tree: the toy tree's leaf-off toy scan (seed 5) and its height."""
    from factories import toy_tree_scan

    return toy_tree_scan()


@pytest.fixture
def served(tmp_path):
    """A running service (a Server on a free local port) over a fresh state folder and a 2-example library."""
    from arboretum_server.service.context import Context
    from arboretum_server.service.dispatch import Dispatcher
    from arboretum_server.service.sessions import Sessions
    from arboretum_server.service.socket import Server
    from factories import make_library, serving

    ctx = Context(Sessions(tmp_path / "state"), make_library(tmp_path / "lib", 2))
    with serving(Server(Dispatcher(ctx), "tcp://127.0.0.1:0")) as server:
        yield server
    ctx.close()
