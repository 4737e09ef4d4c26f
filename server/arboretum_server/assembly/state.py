"""A session's assembly with its undo/redo history, and its autosave (journal + atomic snapshots).

``History`` is immutable: every committed edit is a ``Step`` record (what it did and the Assembly after
it); undo and redo move a cursor. ``Autosave`` makes every commit durable against a killed process before
the caller replies: it appends the edit to ``ID.journal`` (one write per edit, length- and CRC-framed, so
a torn tail is ignored). Every ``SNAPSHOT_EVERY`` edits the journal is renamed ``ID.journal.old`` and a
background thread writes ``ID.npz`` with ``save_record`` (temp file + rename; the history is immutable,
so this never races an edit), then deletes the old journal. Loading replays both journals' entries
newer than the snapshot; if it found an ``ID.journal.old`` (a snapshot cut short by a kill) it writes a
snapshot at once, so later background snapshots go on. If a background snapshot fails (disk full), the
next one first appends the journal to ``ID.journal.old`` and tries again. With ``fsync`` every journal
entry, snapshot file and rename or deletion in the folder is fsynced before it is relied on.
"""

from __future__ import annotations

import logging
import os
import struct
import threading
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import msgpack
import numpy as np

from arboretum_library.assembly import Assembly
from arboretum_library.codec import flatten, fsync_dir, load_record, save_record, unflatten
from arboretum_library.errors import InputError

log = logging.getLogger("arboretum.sessions")
MAX_STEPS = 200
"""Undo depth: older steps are forgotten."""
SNAPSHOT_EVERY = 64
"""Journal entries between snapshots."""
_FRAME = struct.Struct("<II")  # payload length, crc32


@dataclass(frozen=True)
class Step:
    """One committed edit, as a record."""

    label: str
    """What the edit did, e.g. 'add ex-0001 as ex-0001#1'."""
    assembly: Assembly
    """The assembly after the edit."""


@dataclass(frozen=True)
class History:
    """The steps of a session; ``steps[index]`` is the current state."""

    steps: tuple[Step, ...] = (Step("new session", Assembly()),)
    index: int = 0
    revision: int = 0
    """Edits (including undos and redos) committed so far; never goes down."""
    name: str = ""
    """A name for people."""

    @property
    def assembly(self) -> Assembly:
        return self.steps[self.index].assembly

    @property
    def can_undo(self) -> bool:
        return self.index > 0

    @property
    def can_redo(self) -> bool:
        return self.index < len(self.steps) - 1

    def apply(self, label: str, assembly: Assembly) -> History:
        """Commit a new state (dropping any redo steps)."""
        steps = self.steps[: self.index + 1] + (Step(label, assembly),)
        steps = steps[-MAX_STEPS:]
        return replace(self, steps=steps, index=len(steps) - 1, revision=self.revision + 1)

    def undo(self) -> History:
        if not self.can_undo:
            raise InputError("nothing to undo")
        return replace(self, index=self.index - 1, revision=self.revision + 1)

    def redo(self) -> History:
        if not self.can_redo:
            raise InputError("nothing to redo")
        return replace(self, index=self.index + 1, revision=self.revision + 1)

    @property
    def label(self) -> str:
        return self.steps[self.index].label


@dataclass(frozen=True)
class Snapshot:
    """What ``ID.npz`` holds: the history and the journal sequence number it includes."""

    history: History
    seq: int = 0


class Autosave:
    """Durable storage of one session's history in ``folder`` (``ID.npz`` + ``ID.journal``)."""

    def __init__(self, folder: Path, session_id: str, fsync: bool = False) -> None:
        self.snapshot_path = folder / f"{session_id}.npz"
        self.journal_path = folder / f"{session_id}.journal"
        self.old_journal_path = folder / f"{session_id}.journal.old"
        self.fsync = fsync
        self.seq = 0
        self._since_snapshot = 0
        self._writer: threading.Thread | None = None
        folder.mkdir(parents=True, exist_ok=True)

    def load(self) -> History:
        """The saved history (snapshot + journal replay); a fresh one if nothing was saved."""
        history, self.seq = History(), 0
        if self.snapshot_path.exists():
            snap = load_record(self.snapshot_path, Snapshot)
            history, self.seq = snap.history, snap.seq
        old, _ = _read_journal(self.old_journal_path)
        entries = trim_journal(self.journal_path)  # a torn tail cut off before anything is appended
        for entry in old + entries:
            if entry["seq"] <= self.seq:
                continue
            history = _replay(history, entry)
            self.seq = entry["seq"]
            self._since_snapshot += 1
        if self.old_journal_path.exists():  # a snapshot cut short: fold both journals into a new one now
            try:
                self.snapshot(history)
            except OSError as exc:  # the journals still hold every edit; the next snapshot tries again
                log.error("snapshot %s failed: %s", self.snapshot_path, exc)
        return history

    def record(self, history: History, op: str) -> None:
        """Make the edit that produced ``history`` durable (``op``: apply, undo or redo)."""
        self.seq += 1
        entry: dict = {"seq": self.seq, "op": op, "revision": history.revision}
        if op == "apply":
            meta, arrays = flatten(history.steps[history.index])
            entry["step"] = meta
            entry["arrays"] = pack_arrays(arrays)
        else:
            entry["index"] = history.index
        append_entry(self.journal_path, entry, self.fsync)
        self._since_snapshot += 1
        if self._since_snapshot >= SNAPSHOT_EVERY and (self._writer is None or not self._writer.is_alive()):
            self._snapshot_in_background(history)

    def _snapshot_in_background(self, history: History) -> None:
        try:
            self._retire_journal()
        except OSError as exc:  # the journals are as they were: nothing lost, try at the next snapshot
            log.error("snapshot %s postponed: %s", self.snapshot_path, exc)
            return
        snap = Snapshot(history, self.seq)
        self._since_snapshot = 0

        def write() -> None:
            try:
                self._save(snap)
                self.old_journal_path.unlink(missing_ok=True)
                if self.fsync:
                    fsync_dir(self.snapshot_path.parent)
            except OSError as exc:  # keep the old journal: it still holds these edits
                log.error("snapshot %s failed: %s", self.snapshot_path, exc)

        self._writer = threading.Thread(target=write, name=f"snapshot {self.snapshot_path.stem}", daemon=True)
        self._writer.start()

    def _save(self, snap: Snapshot) -> None:
        save_record(self.snapshot_path, snap, fsync=self.fsync)

    def _retire_journal(self) -> None:
        """Move the journal's entries into ``ID.journal.old`` (renamed, or appended after an earlier
        snapshot failed) and start an empty journal; every entry stays in one of the two meanwhile."""
        if not self.old_journal_path.exists():
            os.replace(self.journal_path, self.old_journal_path)
        else:
            entries = self.journal_path.read_bytes()[: _read_journal(self.journal_path)[1]]
            trim_journal(self.old_journal_path)
            with open(self.old_journal_path, "ab") as fh:
                fh.write(entries)
                _sync(fh, self.fsync)
            os.truncate(self.journal_path, 0)
        if self.fsync:
            fsync_dir(self.journal_path.parent)

    def wait(self) -> None:
        """Wait for a background snapshot to finish."""
        if self._writer is not None:
            self._writer.join()

    def snapshot(self, history: History) -> None:
        """Write the whole history atomically and empty the journals (waits for a background one)."""
        self.wait()
        self._save(Snapshot(history, self.seq))
        if self.journal_path.exists():
            os.truncate(self.journal_path, 0)  # its entries are in the snapshot: no fsync needed
        if self.old_journal_path.exists():
            self.old_journal_path.unlink()
            if self.fsync:
                fsync_dir(self.snapshot_path.parent)
        self._since_snapshot = 0

    def delete(self) -> None:
        self.wait()
        for path in (self.snapshot_path, self.journal_path, self.old_journal_path):
            path.unlink(missing_ok=True)


def pack_arrays(arrays: dict[str, np.ndarray]) -> dict[str, list]:
    """Arrays as msgpack-able [dtype, shape, bytes] (for journals we write and read ourselves)."""
    return {k: [a.dtype.str, list(a.shape), np.ascontiguousarray(a).tobytes()] for k, a in arrays.items()}


def unpack_arrays(packed: dict[str, list]) -> dict[str, np.ndarray]:
    return {k: np.frombuffer(b, dtype=d).reshape(s) for k, (d, s, b) in packed.items()}


def append_entry(path: Path, entry: dict, fsync: bool = False) -> None:
    """Append one length- and CRC-framed msgpack entry to the journal ``path`` in a single write."""
    payload = bytes(msgpack.packb(entry, use_bin_type=True) or b"")
    new = fsync and not path.exists()
    with open(path, "ab") as fh:
        fh.write(_FRAME.pack(len(payload), zlib.crc32(payload)) + payload)
        _sync(fh, fsync)
    if new:  # a new file: its name must be durable too
        fsync_dir(path.parent)


def _sync(fh, fsync: bool) -> None:
    if fsync:
        fh.flush()
        os.fsync(fh.fileno())


def trim_journal(path: Path) -> list[dict]:
    """The valid entries of the journal ``path``, its torn or corrupt tail (a kill during an append) cut
    off, so that entries appended next are read back (after a torn tail they would not be)."""
    entries, good = _read_journal(path)
    if path.exists() and good < path.stat().st_size:
        os.truncate(path, good)
    return entries


def _read_journal(path: Path) -> tuple[list[dict], int]:
    """Valid entries of a journal and the byte length they fill (a torn or corrupt tail stops it)."""
    if not path.exists():
        return [], 0
    data = path.read_bytes()
    out, pos = [], 0
    while pos + _FRAME.size <= len(data):
        n, crc = _FRAME.unpack_from(data, pos)
        payload = data[pos + _FRAME.size : pos + _FRAME.size + n]
        if len(payload) < n or zlib.crc32(payload) != crc:
            break
        out.append(msgpack.unpackb(payload, raw=False))
        pos += _FRAME.size + n
    return out, pos


def _replay(history: History, entry: dict) -> History:
    if entry["op"] == "apply":
        step = unflatten(Step, entry["step"], unpack_arrays(entry["arrays"]))
        history = history.apply(step.label, step.assembly)
    else:
        history = replace(history, index=min(entry["index"], len(history.steps) - 1), revision=history.revision + 1)
    return replace(history, revision=entry["revision"])
