"""Where numba keeps the compiled kernels: one folder per version of the kernel sources.

numba checks a cached kernel against its own file only: a kernel that calls a kernel of another file, or
reads a constant from one, keeps running the old code after that file changed (numba's documented cache
limitation). An edited checkout or an updated editable install then gives results of no version of the
code, silently (tests/test_jitcache_s28.py shows it: an edited callee, the caller's old answer). So the
cache lives in a folder named by a digest of every source file of the package that uses numba: a change
to any of them starts from an empty folder, and the older folders are pruned.

numba's cache is also unsafe between processes (session 29): a kernel's compiled versions (one per argument
types: numba compiles ``f(x, 0)`` called from another kernel apart, for ``Literal[int](0)``) go to data files
numbered in the order they were saved, the number chosen from the index the process read. Two processes
compiling different versions at once (a batch build's workers, from an empty cache) both take number 1; the
index can end up naming one version and the file holding the other, and every later process loads the wrong
machine code for those arguments, silently (a shortest path heap run as if empty, an alpha shape judged
open). ``njit`` here installs ``KeyedCacheFile``: a data file named by its key and holding it, written before
the index names it, the index updated under a lock. Every kernel of the server is compiled through it.

A third hazard (numba issue 10486): numba names each compiled function by module, name, argument types and a
number counted from 1 in each process. Two processes can so give one name to two different bodies: two
closures of one factory (numba's own sort and argsort helpers are such closures) compiled at the same count.
A process that loads both cached kernels links every call of that name to whichever body it loaded first, and
the other kernel silently runs the wrong code (session 29: after the synthetic-tree kernel ``throw_darts``
was loaded, ``is_closed_manifold`` sorted its edge keys with another kernel's sort and called a closed
tetrahedron open). ``install`` makes the numbers random (``RandomUids``), so names from different processes,
forked ones too, do not meet.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import secrets
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path

PREFIX = "arboretum-"
"""Name prefix of a kernel-cache folder; the rest is the digest of the kernel sources."""

KEEP = 3
"""Kernel-cache folders kept in one base folder, the current one and the newest others; older ones are removed."""

MARKER = b"numba"
"""A source file whose text holds this is part of the digest (it compiles kernels or imports them)."""

SCHEME = b"keyed-data-files-1 random-uids-1"
"""Part of the digest: the layout of the files in a folder (``KeyedCacheFile``) and the naming of compiled functions
(``RandomUids``). Folders written before session 29 may hold a crossed version or a shared name, so they are never
read again."""


def kernel_digest(package: Path) -> str:
    """16 hex digits of SHA-256 over ``SCHEME`` and the relative path and content of every ``.py`` file under ``package``
    that mentions numba, in sorted order."""
    h = hashlib.sha256(SCHEME + b"\0")
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


def key_tag(key: object) -> str:
    """SHA-256 of a cache key's text (argument types, target machine, byte code): the same in every process."""
    return hashlib.sha256(repr(key).encode()).hexdigest()


@contextlib.contextmanager
def _locked(path: str) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (made if missing) while the block runs; no lock where ``fcntl`` is
    missing (data files are still named by their key there, so a lost index entry costs a compile, never a
    wrong kernel)."""
    try:
        import fcntl
    except ImportError:  # Windows
        yield
        return
    with open(path, "a+b") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


_INSTALLED: list[type | None] = []

UID_BITS = 62
"""Bits of a compiled function's random number (``RandomUids``): two processes compiling n and m functions share a
number with odds of about n * m / 2**62 (a few thousand each: under 1e-11)."""


class RandomUids:
    """numba's counter of compiled functions (``FunctionIdentity._unique_ids``), drawn at random from the
    operating system instead of counted from 1: each process, and each forked child of one, names its
    functions apart from every other's. No number is handed out twice within a process."""

    def __init__(self) -> None:
        self.issued: set[int] = set()

    def __iter__(self) -> RandomUids:
        return self

    def __next__(self) -> int:
        while True:
            uid = secrets.randbits(UID_BITS) | 1 << UID_BITS  # always UID_BITS + 1 bits long
            if uid not in self.issued:
                self.issued.add(uid)
                return uid


NEEDED = ("_load_index", "_save_index", "_load_data", "_save_data")
"""Methods of numba's ``IndexDataCacheFile`` that ``KeyedCacheFile`` builds on (numba 0.60-0.68)."""


def layout_known(cls: type) -> bool:
    """Whether ``cls`` (numba's ``IndexDataCacheFile``) is the layout ``KeyedCacheFile`` was written against:
    its methods ``NEEDED``, an index path and a numbered data-file pattern. A numba that changed them keeps
    its own layout (a warning says so) rather than failing in every compile."""
    try:
        probe = cls(cache_path="", filename_base="probe", source_stamp=None)
    except Exception:  # noqa: BLE001 - any change of the constructor means an unknown layout
        return False
    return (all(callable(getattr(cls, m, None)) for m in NEEDED) and isinstance(getattr(probe, "_index_path", None), str)
            and "{number:d}" in str(getattr(probe, "_data_name_pattern", "")))


def install() -> type | None:
    """Make numba name compiled functions with ``RandomUids`` and its caches use ``KeyedCacheFile`` (once per
    process; numba reads the class name when a kernel with ``cache=True`` is defined, so call this before any
    is). Returns the class; None when this numba's cache files are not the layout it knows (``layout_known``).
    A numba without the counter (a later release) keeps its own, with a warning."""
    if _INSTALLED:
        return _INSTALLED[0]
    import warnings

    from numba.core import bytecode, caching

    if hasattr(bytecode, "FunctionIdentity") and hasattr(bytecode.FunctionIdentity, "_unique_ids"):
        bytecode.FunctionIdentity._unique_ids = RandomUids()  # before any kernel of ours is compiled
    else:
        warnings.warn(f"numba {getattr(sys.modules.get('numba'), '__version__', '?')}: no function counter to "
                      "replace; cached kernels compiled by different processes may share names (numba issue 10486)",
                      RuntimeWarning, stacklevel=2)
    if not layout_known(caching.IndexDataCacheFile):
        warnings.warn(f"numba {getattr(sys.modules.get('numba'), '__version__', '?')}: unknown cache-file layout; "
                      "kernels saved by processes compiling at once may be crossed (see arboretum_server.jitcache)",
                      RuntimeWarning, stacklevel=2)
        _INSTALLED.append(None)
        return None

    unreadable = (OSError, EOFError, ValueError, TypeError, AttributeError, ImportError, IndexError, KeyError,
                  caching.pickle.UnpicklingError)  # what a damaged index or data file raises on reading

    class KeyedCacheFile(caching.IndexDataCacheFile):
        """numba's index and data files, made safe for processes compiling at once: the data file of a version
        is named by ``key_tag`` of its key and stores that tag; it is written whole (numba writes a temporary
        file and renames it) before the index names it; the index is read, extended and written under a lock
        beside it. A load whose file is missing, unreadable or holds another tag returns None: numba compiles."""

        def _keyed_name(self, key: object) -> str:
            return self._data_name_pattern.replace("{number:d}", "k" + key_tag(key)[:24])

        def save(self, key: object, data: object) -> None:
            """Store a compiled version; a folder that cannot be written (removed by ``prune`` in another
            process, a full disk, no permission) leaves it unsaved: the kernel runs, compiled again next time."""
            name = self._keyed_name(key)
            try:
                self._save_data(name, (key_tag(key), data))
                with _locked(self._index_path + ".lock"):
                    overloads = self._index()
                    if overloads.get(key) != name:
                        overloads[key] = name
                        self._save_index(overloads)
            except OSError:
                return

        def load(self, key: object) -> object | None:
            name = self._index().get(key)
            if name is None:
                return None
            try:
                tag, data = self._load_data(name)
            except unreadable:
                return None
            return data if tag == key_tag(key) else None

        def _index(self) -> dict:
            """numba's index, or an empty one when it cannot be read (a truncated or foreign file)."""
            try:
                return self._load_index()
            except unreadable:
                return {}

    caching.IndexDataCacheFile = KeyedCacheFile  # numba.core.caching.Cache looks the name up per kernel
    _INSTALLED.append(KeyedCacheFile)
    return KeyedCacheFile


def njit(*args, **kwargs):
    """``numba.njit`` after ``install`` (random function numbers, ``KeyedCacheFile``): how every kernel of the server
    is compiled."""
    import numba

    install()
    return numba.njit(*args, **kwargs)
