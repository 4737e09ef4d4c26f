"""The write lock of an example library: ``LIB/.lock``, held (``flock``) by the one process writing.
A library whose folder vanished meanwhile is ``LibraryGone``, never recreated by a write.

Any number of processes read without it. A writer waits for it at most a given number of seconds (then
``LibraryBusy``), telling whoever waits through ``on_wait``; the thread holding it may take it again
(the store's own writes inside ``Library.locked()``), other threads of the process wait like other
processes do.
"""

from __future__ import annotations

import contextlib
import fcntl
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from .errors import StoreError
from .recovery import wait_for_lock

LOCK_TIMEOUT_S = 10.0
"""How long a writer waits for another process's write lock by default before ``LibraryBusy``."""

LOCK_FILE = ".lock"


class LibraryBusy(StoreError):
    """Another process held the library's write lock for longer than this one would wait."""

    code = "busy"


class LibraryGone(StoreError):
    """The library's folder (its ``library.json``) is gone while it is open: deleted or moved away."""


def check_present(root: Path) -> None:
    """``LibraryGone`` unless ``root`` still holds the ``library.json`` it was opened with: a library
    deleted (or unmounted) while open is never written (or rebuilt) again as if it were new and empty."""
    if not (root / "library.json").is_file():
        raise _gone(root)


def _gone(root: Path) -> LibraryGone:
    return LibraryGone(f"library {root} is gone (deleted or moved while it was open?)")


class WriteLock:
    """The lock file of the library at ``root``, as one ``Library`` holds it (re-entrant per thread)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._holder: int | None = None  # the thread holding the lock

    def held_here(self) -> bool:
        """True when the calling thread holds the lock (a nested write just goes on)."""
        return self._holder == threading.get_ident()

    @contextlib.contextmanager
    def hold(self, timeout: float | None, on_wait: Callable[[str], None] | None) -> Iterator[None]:
        """Take the lock, waiting at most ``timeout`` seconds (None: as long as it takes) for another
        writer, else ``LibraryBusy``; ``on_wait`` is told once when the wait begins. Ctrl-C stops a wait.
        Call only when not ``held_here()``. ``LibraryGone`` when the library is."""
        check_present(self.root)
        try:
            f = open(self.root / LOCK_FILE, "a+b")  # noqa: SIM115 (a with-block below closes it)
        except FileNotFoundError:  # deleted since the check
            raise _gone(self.root) from None
        with f:
            waiting = f"waiting for the library {self.root}: another process is writing it (Ctrl-C to stop)"
            tell = (lambda: on_wait(waiting)) if on_wait is not None else None
            if not wait_for_lock(f.fileno(), timeout, tell):
                raise LibraryBusy(f"the library {self.root} is being written by another process "
                                  f"(waited {timeout:g} s); try again")
            self._holder = threading.get_ident()
            try:
                yield
            finally:
                self._holder = None
                fcntl.flock(f.fileno(), fcntl.LOCK_UN)
