"""Durable refinement drafts: the scan a draft was decomposed from, and a journal of its edits.

``ID.refine.npz`` (``save_record``: atomic) holds the scan, its options and a generation token;
``ID.refine.journal`` holds each refinement edit (remove / insert / merge / split lobe, undo, redo) with
that token, appended before the reply. After a restart the draft is rebuilt by decomposing the scan
again (deterministic: seeded) and replaying the edits of the current generation, in a worker process.
Only a server of the same ``DECOMPOSE_VERSION`` rebuilds a draft (another would build another tree); a
replay that fails at an edit keeps the edits before it (``keep_first``).
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from arboretum_library.codec import load_record, save_record
from arboretum_library.errors import InputError
from arboretum_server.assembly.state import append_entry, pack_arrays, trim_journal, unpack_arrays

DECOMPOSE_VERSION = 2
"""Version of what ``decompose`` and the refinement edits (``decompose.refine``) compute from a scan, its
options and an edit. Bump it whenever their output changes: a draft records the version it was made with
(records without one are version 1) and is rebuilt only by a server of the same version, since replaying
its edits on another tree changes them or fails. 2: session 12 (split_lobe follows its strokes and refuses
repeated ones; decompose leaves stray groups out)."""


@dataclass(frozen=True, eq=False)
class RefineSource:
    """What a refinement draft was decomposed from."""

    points: np.ndarray
    """(N, 3) float64, metres: the scan as sent."""
    labels: np.ndarray
    """(N,) uint8 WOOD/LEAF labels, or (0,) when none were sent."""
    name: str = "scan"
    species: str = "unknown"
    options: dict = field(default_factory=dict)
    """DecomposeOptions fields as sent."""
    generation: str = ""
    """Token that this draft's journal entries carry."""
    version: int = 1
    """``DECOMPOSE_VERSION`` of the server that made the draft (1: written before versions were recorded)."""


def _paths(folder: Path, sid: str) -> tuple[Path, Path]:
    return folder / f"{sid}.refine.npz", folder / f"{sid}.refine.journal"


def start(folder: Path, sid: str, points: np.ndarray, labels: np.ndarray | None, name: str, species: str,
          options: dict, fsync: bool = False) -> RefineSource:
    """Record a new draft's source (replacing any earlier draft of the session)."""
    src = RefineSource(np.asarray(points, np.float64), np.zeros(0, np.uint8) if labels is None else labels,
                       name, species, dict(options), secrets.token_hex(8), DECOMPOSE_VERSION)
    source, journal = _paths(folder, sid)
    save_record(source, src, fsync=fsync)
    journal.unlink(missing_ok=True)
    return src


def append(folder: Path, sid: str, generation: str, kind: str, args: dict, arrays: dict | None = None,
           fsync: bool = False) -> None:
    """Journal one refinement edit."""
    entry = {"gen": generation, "kind": kind, "args": args, "arrays": pack_arrays(arrays or {})}
    append_entry(_paths(folder, sid)[1], entry, fsync)


def load(folder: Path, sid: str) -> tuple[RefineSource, list[dict]] | None:
    """The saved source and its edits (``kind``, ``args`` with arrays merged in), or None. ``InputError``
    when the draft was made by a server of another ``DECOMPOSE_VERSION`` (its files are left as they are)."""
    source, journal = _paths(folder, sid)
    if not source.exists():
        return None
    src = load_record(source, RefineSource)
    check_version(src, sid)
    entries = trim_journal(journal)
    ops = [{"kind": e["kind"], "args": {**e["args"], **unpack_arrays(e["arrays"])}}
           for e in entries if e.get("gen") == src.generation]
    return src, ops


def check_version(src: RefineSource, sid: str) -> None:
    """``InputError`` unless ``src`` was made by a server of this ``DECOMPOSE_VERSION``."""
    if src.version == DECOMPOSE_VERSION:
        return
    made = "an older" if src.version < DECOMPOSE_VERSION else "a newer"
    raise InputError(f"the refinement draft of session {sid} was made by {made} Arboretum (decomposition "
                     f"version {src.version}; this server's is {DECOMPOSE_VERSION}), which decomposes and splits "
                     f"differently, so it cannot be rebuilt exactly; its files ({sid}.refine.npz, "
                     f"{sid}.refine.journal) are kept; refine.open of the scan again starts over")


def keep_first(folder: Path, sid: str, src: RefineSource, count: int, fsync: bool = False) -> RefineSource:
    """Make the draft's first ``count`` edits its whole journal (a replay failed at the next one): they are
    appended again under a new generation token, then the source is saved with that token (atomic: a crash
    in between leaves the old generation current). The older entries stay in the file, unread."""
    source, journal = _paths(folder, sid)
    kept = [e for e in trim_journal(journal) if e.get("gen") == src.generation][:count]
    new = replace(src, generation=secrets.token_hex(8))
    for e in kept:
        append_entry(journal, {**e, "gen": new.generation}, fsync)
    save_record(source, new, fsync=fsync)
    return new


def delete(folder: Path, sid: str) -> None:
    for p in _paths(folder, sid):
        p.unlink(missing_ok=True)


def remove_orphans(folder: Path, live: list[str] | set[str]) -> list[Path]:
    """Delete the refine files in ``folder`` of sessions not in ``live`` (closed while a job ran, say)."""
    keep = set(live)
    gone = [p for suffix in (".refine.npz", ".refine.journal") for p in folder.glob(f"*{suffix}")
            if p.name[: -len(suffix)] not in keep]
    for p in gone:
        p.unlink(missing_ok=True)
    return gone
