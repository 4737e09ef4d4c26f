"""Where numba keeps the compiled kernels: one folder per version of the kernel sources.

numba checks a cached kernel against its own file only: a kernel that calls a kernel of another file, or
reads a constant from one, keeps running the old code after that file changed (numba's documented cache
limitation). An edited checkout or an updated editable install then gives results of no version of the
code, silently (tests/test_jitcache_s28.py shows it: an edited callee, the caller's old answer). So the
cache lives in a folder named by a digest of every source file of the package that uses numba: a change
to any of them starts from an empty folder, and the older folders are pruned.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

PREFIX = "arboretum-"
"""Name prefix of a kernel-cache folder; the rest is the digest of the kernel sources."""

KEEP = 3
"""Kernel-cache folders kept in one base folder, the current one and the newest others; older ones are removed."""

MARKER = b"numba"
"""A source file whose text holds this is part of the digest (it compiles kernels or imports them)."""


def kernel_digest(package: Path) -> str:
    """16 hex digits of SHA-256 over the relative path and content of every ``.py`` file under ``package``
    that mentions numba, in sorted order."""
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        data = path.read_bytes()
        if MARKER in data:
            h.update(path.relative_to(package).as_posix().encode() + b"\0" + data + b"\0")
    return h.hexdigest()[:16]


def default_base(package: Path) -> Path:
    """The package's own ``__pycache__/numba`` when it can be written (numba's own default place), else the
    user's cache folder (``$XDG_CACHE_HOME/arboretum/numba``)."""
    here = package / "__pycache__" / "numba"
    try:
        here.mkdir(parents=True, exist_ok=True)
        if os.access(here, os.W_OK):
            return here
    except OSError:
        pass
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "arboretum" / "numba"


def cache_dir(package: Path, base: Path | None = None) -> Path:
    """The kernel-cache folder for the sources under ``package`` now: ``base / PREFIX + digest``. A base that
    already is such a folder (inherited by a child process) is kept when its digest matches."""
    name = PREFIX + kernel_digest(package)
    base = base if base is not None else default_base(package)
    return base if base.name == name else (base.parent if base.name.startswith(PREFIX) else base) / name


def prune(current: Path, keep: int = KEEP) -> list[Path]:
    """Remove the kernel-cache folders beside ``current`` but the ``keep`` newest (``current`` always
    stays); the removed ones, for the caller to report. A folder another process still reads is only
    compiled again there (numba tolerates missing cache files)."""
    others = [p for p in current.parent.glob(PREFIX + "*") if p.is_dir() and p != current]
    others.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    gone = others[max(0, keep - 1):]
    for p in gone:
        shutil.rmtree(p, ignore_errors=True)
    return gone


def use(package: Path) -> Path | None:
    """Point numba's cache at ``cache_dir(package)`` (under ``NUMBA_CACHE_DIR`` when the user set one) for
    this process and its children; call before any kernel module is imported. None, and numba's own
    places, when no folder can be made."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    try:
        target = cache_dir(package, Path(given) if given else None)
        target.mkdir(parents=True, exist_ok=True)
        prune(target)
    except OSError:
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(target)  # numba reads it on import and again before each compile
    if "numba" in sys.modules:
        sys.modules["numba"].config.CACHE_DIR = str(target)
    return target
