"""Whole-or-nothing file writes and a Ctrl-C deferral for blocks that must not be cut short.

``write_files_atomic`` writes a set of files through temporary files beside them and puts them in place
all or none (``replace_all``), so an export is either the old set or the new one, even when a rename
fails partway (a folder made read-only, a destination that became a folder, a full disk).
``interruptible`` is that hold: it notes a Ctrl-C (SIGINT) during the block and raises
``KeyboardInterrupt`` once the block has ended. The synth stage wraps its numba kernels in it too:
compiled code does not stop for a signal, and a ``KeyboardInterrupt`` raised while numba converts
arguments or results comes out as its ``SystemError`` (or, in the Yao-graph kernels, a segmentation
fault); an exception leaving the block after a Ctrl-C therefore becomes ``KeyboardInterrupt``.
Standard library only.
"""

from __future__ import annotations

import errno
import os
import signal
import stat
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
    """Write every (path, data) to a temporary file beside it, then put them all in place, all or none
    (``replace_all``); on an error or interrupt before the renames, every temporary file is removed and
    no ``path`` changes."""
    temps: list[str] = []
    try:
        for path, data in files:
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            temps.append(tmp)
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.chmod(tmp, FILE_MODE)
        replace_all([(Path(tmp), path) for (path, _), tmp in zip(files, temps)])
    except BaseException:
        for tmp in temps:
            Path(tmp).unlink(missing_ok=True)
        raise


class NotReplaced(OSError):
    """``replace_all`` could not put ``filename`` (its pair number ``index``) in place and undid what it had
    done; ``lost`` names what it could not put back ('' when every destination holds its old file)."""

    def __init__(self, exc: OSError, filename: Path, index: int, lost: str):
        super().__init__(exc.errno, exc.strerror or str(exc), str(filename))
        self.index, self.lost = index, lost


def replace_all(pairs: Sequence[tuple[Path, Path]]) -> None:
    """Rename each new file ``tmp`` to its destination ``out`` ((tmp, out) pairs), all or none, with Ctrl-C
    held back over the whole swap.

    Each present destination is first kept under a second hidden name beside it, ``tmp``'s name with
    ``.old`` for ``.tmp`` (a hard link, so the destination stays in place; moved aside where the folder
    has no hard links); then the new files are renamed in. An ``OSError`` at any step undoes the steps
    done, newest first (every destination holds what it held before, a missing one is missing again),
    removes the temporary files and raises ``NotReplaced``. On success the ``.old`` files go. A SIGKILL
    during the swap can leave ``.tmp`` (the new file) and ``.old`` (the previous one) files beside a
    destination; neither is ever read."""
    kept: list[tuple[Path | None, bool]] = []
    placed = 0
    with interruptible():
        try:
            for tmp, out in pairs:
                kept.append(set_aside(tmp, out))
            for tmp, out in pairs:
                os.replace(tmp, out)
                placed += 1
        except BaseException as exc:
            lost = _roll_back(pairs, kept, placed)
            if not isinstance(exc, OSError):
                raise
            i = len(kept) if len(kept) < len(pairs) else placed  # a set-aside or a rename failed
            raise NotReplaced(exc, pairs[i][1], i, lost) from None
        for old, _ in kept:
            if old is not None:
                old.unlink(missing_ok=True)


def set_aside(tmp: Path, out: Path) -> tuple[Path | None, bool]:
    """Keep the file now at ``out`` under ``tmp``'s name with ``.old`` (a free one: ``.1.old``, ...
    after a killed run): (that path, whether it is a hard link, ``out`` left in place), or (None, False)
    when there is none. ``OSError`` when it cannot be kept (a folder is refused: a file must not replace
    it)."""
    try:
        if stat.S_ISDIR(os.lstat(out).st_mode):
            raise IsADirectoryError(errno.EISDIR, "it is a folder now", str(out))
    except FileNotFoundError:
        return None, False
    base, k = tmp.name.removesuffix(".tmp"), 0
    old = tmp.with_name(f"{base}.old")
    while os.path.lexists(old):  # left by a killed run that had the same name
        k += 1
        old = tmp.with_name(f"{base}.{k}.old")
    try:
        os.link(out, old, follow_symlinks=False)  # a link to the entry itself, as the rename replaces it
        return old, True
    except FileExistsError:  # taken since it was looked at: never replace a file we did not write
        raise
    except OSError:  # a folder without hard links (FAT, some network shares): move the file aside
        os.rename(out, old)
        return old, False


def _put_back(out: Path, old: Path | None, linked: bool, placed: bool) -> None:
    """Undo ``set_aside`` (and the rename of the new file to ``out`` when ``placed``)."""
    if old is None:
        if placed:
            os.unlink(out)
    elif placed or not linked:
        os.replace(old, out)
    else:
        os.unlink(old)


def _roll_back(pairs: Sequence[tuple[Path, Path]], kept: list[tuple[Path | None, bool]], placed: int) -> str:
    """Put back, newest first, what ``replace_all`` did; remove the temporary files. '' when every
    destination holds its old file again, else what could not be put back (its previous file stays aside)."""
    lost = []
    for i in reversed(range(len(kept))):
        old, linked = kept[i]
        out = pairs[i][1]
        try:
            _put_back(out, old, linked, i < placed)
        except OSError as exc:
            where = f"its previous file is {old}" if old is not None else "it is new"
            lost.append(f"{out} ({where}: {exc.strerror or exc})")
    for tmp, _ in pairs:
        tmp.unlink(missing_ok=True)
    return f"could not put back {', '.join(lost)}" if lost else ""


def write_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and ``os.replace`` (no half-written files)."""
    write_files_atomic([(Path(path), data)])
