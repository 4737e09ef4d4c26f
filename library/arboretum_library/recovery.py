"""Crash consistency of an example library: write journals, and reconciling after a crash.

Every write (add, replace, delete) first drops a small journal file in ``LIB/.tmp/`` naming the
operation and the id, then renames whole folders and commits the catalog, then removes the journal.
Writers hold the library's lock file while they do so, so a writer that finds anything in ``.tmp/``
while holding the lock knows it is a crash leftover and calls ``reconcile``, which finishes or undoes
each journalled operation, empties ``.tmp/``, re-indexes orphan folders (or moves broken ones to
``LIB/quarantine/``) and drops rows whose folder is gone.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path

from . import catalog
from .errors import StoreError
from .folders import fsync_path, read_folder, write_bytes

JOURNAL_PREFIX = "journal-"


@dataclass
class Recovery:
    """What ``reconcile`` did."""

    reindexed: list[str] = field(default_factory=list)
    """Ids whose folder was (re-)entered in the catalog from its meta.json."""
    quarantined: list[str] = field(default_factory=list)
    """Names of folders moved to ``quarantine/`` because they were broken."""
    dropped: list[str] = field(default_factory=list)
    """Ids whose catalog row was removed because their folder is gone."""
    cleaned: int = 0
    """Entries removed from ``.tmp/``."""


def unique(prefix: str) -> str:
    """A name no other process will pick: prefix, pid and random hex."""
    return f"{prefix}{os.getpid()}-{secrets.token_hex(6)}"


def write_journal(tmp: Path, op: str, id_: str, aside: str | None, durable: bool) -> Path:
    """Record that ``op`` on ``id_`` is under way (``aside``: where a replaced folder was moved)."""
    path = tmp / f"{unique(JOURNAL_PREFIX)}.json"
    write_bytes(path, json.dumps({"op": op, "id": id_, "aside": aside}).encode(), durable)
    if durable:
        fsync_path(tmp)
    return path


def _transaction(con: sqlite3.Connection):
    con.execute("BEGIN IMMEDIATE")
    return con


def _index_folder(con: sqlite3.Connection, folder: Path, report: Recovery) -> bool:
    """Upsert the row of the example in ``folder``; False when the folder is broken."""
    try:
        entry = read_folder(folder).entry
    except StoreError:
        return False
    if entry.id != folder.name:
        return False
    _transaction(con)
    catalog.upsert(con, entry)
    con.execute("COMMIT")
    report.reindexed.append(entry.id)
    return True


def _finish(con: sqlite3.Connection, root: Path, journal: dict, report: Recovery) -> None:
    """Complete (or roll back) one journalled operation."""
    id_, op = journal.get("id"), journal.get("op")
    if not isinstance(id_, str) or "/" in id_ or id_ in ("", ".", ".."):
        return
    target = root / "examples" / id_
    if op == "delete":
        _transaction(con)
        catalog.remove(con, [id_])
        con.execute("COMMIT")
        if target.exists():
            shutil.rmtree(target)
        return
    aside = journal.get("aside")
    if not target.exists() and isinstance(aside, str) and (root / ".tmp" / aside).is_dir():
        os.rename(root / ".tmp" / aside, target)  # a replace crashed between its two renames
    if target.exists():
        if not _index_folder(con, target, report):
            _quarantine(con, root, target, report)
    elif catalog.get(con, id_) is not None:
        _transaction(con)
        catalog.remove(con, [id_])
        con.execute("COMMIT")
        report.dropped.append(id_)


def _quarantine(con: sqlite3.Connection, root: Path, path: Path, report: Recovery) -> None:
    qdir = root / "quarantine"
    qdir.mkdir(exist_ok=True)
    name = f"{path.name}-{secrets.token_hex(4)}"
    os.rename(path, qdir / name)
    _transaction(con)
    catalog.remove(con, [path.name])
    con.execute("COMMIT")
    report.quarantined.append(name)


def _clean_tmp(con: sqlite3.Connection, root: Path, report: Recovery) -> None:
    tmp = root / ".tmp"
    journals = sorted(tmp.glob(f"{JOURNAL_PREFIX}*.json"), key=lambda p: p.stat().st_mtime)
    for path in journals:
        try:
            journal = json.loads(path.read_text())
        except (OSError, ValueError):
            continue  # torn journal: its operation had not renamed anything yet
        if isinstance(journal, dict):
            _finish(con, root, journal, report)
    for path in tmp.iterdir():
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
        report.cleaned += 1


def reconcile(con: sqlite3.Connection, root: Path, full: bool) -> Recovery:
    """Bring folders and catalog back in step (call with the write lock held).

    ``full`` also compares every folder name with every row (done when a writer opens the library);
    otherwise only the journals and leftovers in ``.tmp/`` are handled.
    """
    report = Recovery()
    _clean_tmp(con, root, report)
    if full:
        examples = root / "examples"
        on_disk = {p.name: p for p in examples.iterdir()}
        rows = set(catalog.ids(con))
        for name in sorted(on_disk.keys() - rows):
            path = on_disk[name]
            if not (path.is_dir() and _index_folder(con, path, report)):
                _quarantine(con, root, path, report)
        gone = sorted(rows - on_disk.keys())
        if gone:
            _transaction(con)
            catalog.remove(con, gone)
            con.execute("COMMIT")
            report.dropped.extend(gone)
    return report
