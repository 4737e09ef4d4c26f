"""Crash consistency of an example library: write journals, and reconciling after a crash.

Every write (add, replace, delete) first drops a small journal file in ``LIB/.tmp/`` naming the
operation and the id, then renames whole folders and commits the catalog, then removes the journal; a
group add journals all its ids once, and a failed one is taken back without writing (``take_back``).
Writers hold the library's lock file while they do so, so a writer that finds anything in ``.tmp/``
while holding the lock knows it is a crash leftover and calls ``reconcile``, which finishes or undoes
each journalled operation, empties ``.tmp/``, re-indexes orphan folders (or moves broken ones to
``LIB/quarantine/``) and drops rows whose folder is gone. ``open_catalog`` rebuilds a missing or damaged
catalog from the folders (keeping the damaged file aside); ``wait_for_lock`` takes the lock with a deadline.
"""

from __future__ import annotations

import fcntl
import json
import os
import secrets
import shutil
import sqlite3
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from . import catalog
from .errors import StoreError
from .folders import (
    QUARANTINE,
    fsync_path,
    now_utc,
    quarantine_name,
    read_folder,
    valid_id,
    write_bytes,
)

JOURNAL_PREFIX = "journal-"
CATALOG = "catalog.sqlite"
_FRESH_PREFIX = ".catalog-new-"


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
    catalog_problem: str = ""
    """Why the catalog was rebuilt from the folders ('is missing', 'is damaged (...)'); '' when it was not."""
    catalog_kept: str = ""
    """Where the damaged catalog file was moved ('' when none was)."""

    def merge(self, other: Recovery) -> Recovery:
        """This report with ``other``'s findings appended."""
        self.reindexed += other.reindexed
        self.quarantined += other.quarantined
        self.dropped += other.dropped
        self.cleaned += other.cleaned
        return self


def unique(prefix: str) -> str:
    """A name no other process will pick: prefix, pid and random hex."""
    return f"{prefix}{os.getpid()}-{secrets.token_hex(6)}"


def write_journal(tmp: Path, op: str, id_: str, aside: str | None, durable: bool,
                  ids: list[str] | None = None) -> Path:
    """Record that ``op`` on ``id_`` is under way (``aside``: where a replaced folder was moved).

    ``op`` "add_group" with ``ids``: examples added all or none; a crash rolls every one of them back.
    """
    path = tmp / f"{unique(JOURNAL_PREFIX)}.json"
    try:
        write_bytes(path, json.dumps({"op": op, "id": id_, "aside": aside, "ids": ids}).encode(), durable)
        if durable:
            fsync_path(tmp)
    except BaseException:  # a full disk, Ctrl-C: nothing was done yet, so no torn journal is left
        path.unlink(missing_ok=True)
        raise
    return path


def take_back(con: sqlite3.Connection, root: Path, ids: list[str], staged: list[Path]) -> bool:
    """Undo a group add (``ids``) that failed before it finished, deleting its folders in ``examples/``
    and its staging folders ``staged``; True when all is undone, False when something could not be
    (its group journal, still in ``.tmp/``, then makes the next writer finish). Needs no free space: no
    journal is written (the group journal names every id), and the catalog never held their rows (they
    are removed only if a COMMIT that reported an error went through after all)."""
    try:
        if any(catalog.get(con, id_) is not None for id_ in ids):
            catalog.write(con, lambda c: catalog.remove(c, ids))
        for path in [root / "examples" / id_ for id_ in ids] + staged:
            if path.exists():
                shutil.rmtree(path)
    except (OSError, sqlite3.Error):
        return False
    return True


def _index_folder(con: sqlite3.Connection, folder: Path, report: Recovery) -> bool:
    """Upsert the row of the example in ``folder``; False when the folder is broken."""
    try:
        entry = read_folder(folder).entry
    except StoreError:
        return False
    if entry.id != folder.name:
        return False
    catalog.write(con, lambda c: catalog.upsert(c, entry))
    report.reindexed.append(entry.id)
    return True


def _finish(con: sqlite3.Connection, root: Path, journal: dict, report: Recovery) -> None:
    """Complete (or roll back) one journalled operation."""
    id_, op = journal.get("id"), journal.get("op")
    if op == "add_group" and isinstance(journal.get("ids"), list):
        ids = [one for one in journal["ids"] if isinstance(one, str) and valid_id(one)]
        catalog.write(con, lambda c: catalog.remove(c, ids))  # the whole group's rows in one go: all or none
        for one in ids:
            if (root / "examples" / one).exists():
                shutil.rmtree(root / "examples" / one)
        return
    if not isinstance(id_, str) or not valid_id(id_):
        return
    target = root / "examples" / id_
    if op == "delete":
        catalog.write(con, lambda c: catalog.remove(c, [id_]))
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
        catalog.write(con, lambda c: catalog.remove(c, [id_]))
        report.dropped.append(id_)


def _quarantine(con: sqlite3.Connection, root: Path, path: Path, report: Recovery) -> None:
    qdir = root / QUARANTINE
    qdir.mkdir(exist_ok=True)
    name = quarantine_name(path.name, secrets.token_hex(4))
    os.rename(path, qdir / name)
    catalog.write(con, lambda c: catalog.remove(c, [path.name]))
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
            catalog.write(con, lambda c: catalog.remove(c, gone))
            report.dropped.extend(gone)
    return report


def wait_for_lock(fd: int, timeout: float | None, on_wait: Callable[[], None] | None = None) -> bool:
    """Take an exclusive ``flock`` on ``fd``, polling; False when ``timeout`` seconds (None: never)
    passed first. ``on_wait`` is called once when the lock is found taken. Ctrl-C interrupts the wait."""
    deadline = None if timeout is None else time.monotonic() + max(timeout, 0.0)
    delay = 0.005
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            pass
        left = None if deadline is None else deadline - time.monotonic()
        if left is not None and left <= 0:
            return False
        if on_wait is not None:
            on_wait()
            on_wait = None
        time.sleep(delay if left is None else min(delay, left))
        delay = min(delay * 2, 0.1)


def open_catalog(root: Path, durable: bool, report: Recovery) -> sqlite3.Connection:
    """Connect to ``root/catalog.sqlite`` for writing (call with the write lock held); when it is missing
    or damaged, move what is left of it aside (``catalog.sqlite.damaged-TIME``), build a new one from the
    example folders under a temporary name and rename it into place, so readers never see it half-built."""
    db = root / CATALOG
    try:
        catalog.connect(db, readonly=True, durable=durable).close()  # leaves a damaged file as it is
        return catalog.connect(db, readonly=False, durable=durable, check=False)
    except catalog.CatalogDamaged as exc:
        leftovers = [p for p in (db, *_sidecars(db)) if p.exists()]
        if leftovers or any((root / "examples").iterdir()):
            report.catalog_problem = exc.reason
        if leftovers:
            report.catalog_kept = str(_move_aside(db))
    for old in root.glob(f"{_FRESH_PREFIX}*"):  # a rebuild that crashed (derived data: safe to drop)
        old.unlink()
    fresh = root / unique(_FRESH_PREFIX)
    catalog.create(fresh)
    con = catalog.connect(fresh, readonly=False, durable=durable)
    try:
        report.merge(reconcile(con, root, full=True))
    finally:
        con.close()  # checkpoints and removes its WAL, so the file is whole under its new name
    os.replace(fresh, db)
    if durable:
        fsync_path(root)
    return catalog.connect(db, readonly=False, durable=durable, check=False)


def _sidecars(db: Path) -> tuple[Path, Path]:
    return db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm")


def _move_aside(db: Path) -> Path:
    """Rename the catalog and its WAL files to ``catalog.sqlite.damaged-TIME[-N]`` (kept, never deleted)."""
    stamp = now_utc().replace("-", "").replace(":", "")
    kept = db.with_name(f"{db.name}.damaged-{stamp}")
    n = 1
    while kept.exists() or any(p.exists() for p in _sidecars(kept)):
        n += 1
        kept = db.with_name(f"{db.name}.damaged-{stamp}-{n}")
    for src, dst in zip((db, *_sidecars(db)), (kept, *_sidecars(kept)), strict=True):
        if src.exists():
            os.rename(src, dst)
    return kept
