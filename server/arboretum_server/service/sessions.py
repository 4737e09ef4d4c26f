"""Sessions: each client's assembly history (autosaved on every commit) and refinement draft.

A session lives in ``STATE/sessions/ID.npz`` + ``ID.journal`` (see ``assembly.state.Autosave``); every
session found there is loaded when the server starts, so a server killed with SIGKILL comes back with
every edit it had acknowledged. The refinement draft (a ``Decomposition`` with its cached graph) lives in
memory, and its source scan and edits in ``ID.refine.npz`` + ``ID.refine.journal`` (``refine_store``): after a
restart, the first refinement request rebuilds it in a worker.

A session whose files cannot be read (a snapshot cut short, garbage) is skipped at start-up with an
error in the log, and all its files are moved into ``STATE/sessions/damaged/`` (never deleted). Refine
files whose session is gone (closed while a job ran, say) are deleted at start-up.
"""

from __future__ import annotations

import logging
import os
import secrets
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from arboretum_library.errors import ArboretumError, InputError
from arboretum_server.assembly.state import Autosave, History

log = logging.getLogger("arboretum.sessions")


class NotFound(ArboretumError):
    """A session, placement or example that does not exist."""

    code = "not_found"


@dataclass
class RefineDraft:
    """Undoable refinement states of one decomposed scan (``states[index]`` is current)."""

    states: list[Any]
    index: int = 0
    name: str = "scan"
    species: str = "unknown"
    revision: int = 0
    generation: str = ""
    """Token of the saved source this draft journals its edits under (``refine_store``). A commit of a
    draft already in the library is found by content in the library itself (``handlers.refine._copies``)."""

    @property
    def current(self) -> Any:
        return self.states[self.index]

    def push(self, state: Any) -> None:
        self.states = self.states[: self.index + 1] + [state]
        self.states = self.states[-50:]
        self.index = len(self.states) - 1
        self.revision += 1

    def move(self, step: int) -> None:
        target = self.index + step
        if not 0 <= target < len(self.states):
            raise InputError("nothing to " + ("undo" if step < 0 else "redo") + " in the refinement")
        self.index = target
        self.revision += 1


@dataclass
class Session:
    id: str
    history: History
    autosave: Autosave
    refine: RefineDraft | None = None
    busy: set = field(default_factory=set)

    def commit(self, history: History, op: str = "apply") -> None:
        """Make ``history`` current and durable (before the caller replies)."""
        self.autosave.record(history, op)
        self.history = history


class Sessions:
    """Every session of a server, loaded from and saved to ``folder``."""

    def __init__(self, folder: str | Path | None, fsync: bool = False) -> None:
        self.folder = Path(folder) / "sessions" if folder is not None else None
        self.fsync = fsync
        self._all: dict[str, Session] = {}
        self._memory_dir: Path | None = None
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            for sid in saved_ids(self.folder):
                self._load(sid)
            from .refine_store import remove_orphans

            gone = remove_orphans(self.folder, saved_ids(self.folder))
            if gone:
                log.warning("removed %d refine file(s) of sessions that no longer exist", len(gone))

    def _load(self, sid: str) -> None:
        """Load session ``sid`` from the folder; log and skip it (moving a damaged one aside) if it fails."""
        assert self.folder is not None
        try:
            auto = Autosave(self.folder, sid, self.fsync)
            self._all[sid] = Session(sid, auto.load(), auto)
        except ArboretumError as exc:
            try:
                moved = f"were moved to {move_aside(self.folder, sid)}"
            except OSError as err:
                moved = f"could not be moved aside ({err})"
            log.error("session %s could not be loaded: %s; its files %s", sid, exc, moved)
        except OSError as exc:
            log.error("session %s could not be read: %s", sid, exc)

    def new(self, name: str = "", history: History | None = None) -> Session:
        sid = secrets.token_hex(8)
        h = history or History()
        if name:
            h = History(h.steps, h.index, h.revision, name)
        s = Session(sid, h, Autosave(self.dir(), sid, self.fsync))
        s.autosave.snapshot(s.history)
        self._all[sid] = s
        return s

    def dir(self) -> Path:
        """The folder of the session files."""
        if self.folder is not None:
            return self.folder
        if self._memory_dir is None:
            import tempfile

            self._memory_dir = Path(tempfile.mkdtemp(prefix="arboretum-sessions-"))
        return self._memory_dir

    def get(self, sid: str) -> Session:
        s = self._all.get(sid)
        if s is None:
            raise NotFound(f"no session {sid[:40]!r} on this server")
        return s

    def still_open(self, s: Session) -> Session:
        """``s`` if it was not closed meanwhile (a job's result arriving late); ``NotFound`` otherwise."""
        if self._all.get(s.id) is not s:
            raise NotFound(f"session {s.id[:40]!r} was closed while this request ran")
        return s

    def close(self, sid: str) -> None:
        from .refine_store import delete

        self.get(sid).autosave.delete()
        delete(self.dir(), sid)
        del self._all[sid]

    def all(self) -> list[Session]:
        return list(self._all.values())

    def snapshot_all(self) -> None:
        """Write every session's snapshot (on a clean shutdown)."""
        for s in self._all.values():
            s.autosave.snapshot(s.history)


def _valid(sid: str) -> bool:
    return 0 < len(sid) <= 64 and all(c in "0123456789abcdef" for c in sid)


SESSION_FILES = (".npz", ".journal", ".journal.old")
"""Suffixes of a session's autosave files (``assembly.state.Autosave``)."""


def saved_ids(folder: Path) -> list[str]:
    """Ids of the sessions with autosave files in ``folder``."""
    names = {p.name.split(".", 1)[0] for suffix in SESSION_FILES for p in folder.glob(f"*{suffix}")
             if p.name.endswith(suffix) and p.name.count(".") == suffix.count(".")}
    return sorted(n for n in names if _valid(n))


def move_aside(folder: Path, sid: str) -> Path:
    """Move every file of session ``sid`` into ``folder/damaged`` (no name is ever overwritten)."""
    dest = folder / "damaged"
    dest.mkdir(exist_ok=True)
    for p in sorted(folder.glob(f"{sid}.*")):
        target, n = dest / p.name, 1
        while target.exists():
            target, n = dest / f"{p.name}.{n}", n + 1
        os.replace(p, target)
    return dest
