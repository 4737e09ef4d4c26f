"""Whole-or-nothing file writes and a Ctrl-C deferral for blocks that must not be cut short.

``write_files_atomic`` writes a set of files through temporary files beside them and renames them with
Ctrl-C held back until the last rename, so an export is either the old set or the new one.
``interruptible`` is that hold: it notes a Ctrl-C (SIGINT) during the block and raises
``KeyboardInterrupt`` once the block has ended. The synth stage wraps its numba kernels in it too:
compiled code does not stop for a signal, and a ``KeyboardInterrupt`` raised while numba converts
arguments or results comes out as its ``SystemError`` (or, in the Yao-graph kernels, a segmentation
fault); an exception leaving the block after a Ctrl-C therefore becomes ``KeyboardInterrupt``.
Standard library only.
"""

from __future__ import annotations

import os
import signal
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path


def _process_umask() -> int:
    """The process's umask: from /proc on Linux (read, not changed), else set and restored once."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


FILE_MODE = 0o666 & ~_process_umask()
"""Mode of the files written here, read once at import (toggling the umask per write would race with
other threads creating files)."""


@contextmanager
def interruptible() -> Iterator[None]:
    """Defer Ctrl-C (SIGINT) to the end of the block, then raise ``KeyboardInterrupt``.

    An exception leaving the block after a Ctrl-C becomes ``KeyboardInterrupt`` (numba wraps one raised
    inside its kernels). Only when Python's default handler is installed and this is the main thread
    (the only thread that may change a handler); otherwise the block runs unchanged.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):  # fmt: skip
        yield
        return
    caught: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    except BaseException:
        if caught:
            raise KeyboardInterrupt from None
        raise
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if caught:
        raise KeyboardInterrupt


def write_files_atomic(files: Sequence[tuple[Path, bytes]]) -> None:
    """Write every (path, data) to a temporary file beside it, then rename them in order with Ctrl-C held
    back until the last rename (the set is replaced whole); on an error or interrupt before the renames,
    every temporary file is removed and no ``path`` changes."""
    temps: list[str] = []
    try:
        for path, data in files:
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            temps.append(tmp)
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.chmod(tmp, FILE_MODE)
        with interruptible():
            for (path, _), tmp in zip(files, temps):
                os.replace(tmp, path)
    except BaseException:
        for tmp in temps:
            Path(tmp).unlink(missing_ok=True)
        raise


def write_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and ``os.replace`` (no half-written files)."""
    write_files_atomic([(Path(path), data)])
