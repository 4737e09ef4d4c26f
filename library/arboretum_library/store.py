"""The example library on disk: whole example folders plus a SQLite catalog (see docs/library.md).

Layout::

    LIB/library.json            format marker and schema version
    LIB/catalog.sqlite          the index (WAL mode; derived from the folders, rebuilt if lost)
    LIB/examples/<id>/          meta.json + arrays.npz of one example
    LIB/.tmp/                   staging folders and write journals (empty when no write is under way)
    LIB/.lock                   held (flock) by a process while it writes
    LIB/quarantine/             broken folders found when reconciling

A ``Library`` holds a path and one SQLite connection; use one per thread. Any number of processes can
read while one writes; writers take turns through the lock file.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import sqlite3
from collections.abc import Iterable, Iterator
from dataclasses import replace as with_fields
from pathlib import Path

import numpy as np

from . import catalog
from . import search as _search
from .catalog import SCHEMA_VERSION, Entry
from .descriptors import CURVATURE_TAGS, relative_curvature_tags, tercile_bounds
from .errors import InputError, StoreError
from .folders import (
    encode,
    entry_for,
    exchange,
    fsync_path,
    now_utc,
    read_folder,
    valid_id,
    write_folder,
)
from .model import Example
from .progress import ProgressFn, no_progress
from .recovery import Recovery, reconcile, unique, write_journal

LIBRARY_FORMAT = "arboretum-library"


class Library:
    """An open example library. Create with ``Library.open``; close with ``close()`` or ``with``."""

    def __init__(self, root: Path, con: sqlite3.Connection, readonly: bool, durable: bool) -> None:
        self.root = root
        self._con = con
        self.readonly = readonly
        self.durable = durable
        self.recovered = Recovery()
        """What reconciling did when this (writing) library was opened."""

    # -- opening -----------------------------------------------------------------------------
    @classmethod
    def open(cls, path: str | os.PathLike, create: bool = False, *, readonly: bool = False,
             fsync: bool = True) -> Library:
        """Open the library at ``path`` (``create``: make it if missing). ``InputError`` if it is not one.

        ``readonly`` opens never write or reconcile; ``fsync`` makes every write durable on power loss.
        """
        root = Path(path)
        _check_marker(root, create and not readonly)
        con = catalog.connect(root / "catalog.sqlite", readonly=readonly, durable=fsync)
        lib = cls(root, con, readonly, fsync)
        if readonly:
            return lib
        try:
            for sub in ("examples", ".tmp"):
                (root / sub).mkdir(exist_ok=True)
            with lib._lock(finish_crashed=False):
                lib.recovered = reconcile(con, root, full=True)
        except BaseException:
            con.close()
            raise
        return lib

    def close(self) -> None:
        self._con.close()

    def __enter__(self) -> Library:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- reading -----------------------------------------------------------------------------
    def ids(self) -> list[str]:
        """Every example id, sorted."""
        return catalog.ids(self._con)

    def __len__(self) -> int:
        return self._con.execute("SELECT COUNT(*) FROM examples").fetchone()[0]

    def __contains__(self, id_: object) -> bool:
        return isinstance(id_, str) and catalog.get(self._con, id_) is not None

    def entry(self, id_: str) -> Entry:
        """The catalog row of ``id_`` (no arrays loaded), with the library's 'straight'/'curved' (``entries``)."""
        e = catalog.get(self._con, id_)
        if e is None:
            raise StoreError(f"no example {id_!r} in library {self.root}")
        return self._relative([e])[0]

    def entries(self, **filters) -> list[Entry]:
        """Catalog rows passing ``filters``, by id: ``species``, ``tags`` (all of them), ``min_lobes``,
        ``max_lobes``, ``min_curvature``, ``max_curvature`` (radians; ranges inclusive).

        'straight' and 'curved' are relative to the library: the straighter and curvier thirds of each
        species with enough examples (``descriptors.relative_curvature_tags``); the rows carry these.
        """
        tags = filters.get("tags") or ()
        want = tuple(t.lower() for t in ((tags,) if isinstance(tags, str) else tags))
        filters["tags"] = tuple(t for t in want if t not in CURVATURE_TAGS)
        rows = self._relative(catalog.select(self._con, **filters))
        return [e for e in rows if all(t in e.tags for t in want if t in CURVATURE_TAGS)]

    def _relative(self, rows: list[Entry]) -> list[Entry]:
        """``rows`` with 'straight'/'curved' decided by the terciles of their species in the library."""
        if not rows:
            return rows
        bounds = {k: tercile_bounds(np.array(v)) for k, v in catalog.curvature_by_species(self._con).items()}
        return [with_fields(e, tags=relative_curvature_tags(e.tags, e.descriptors.curvature, bounds.get(e.species)))
                for e in rows]

    def get(self, id_: str) -> Example:
        """Load example ``id_`` whole. ``StoreError`` names the id when missing, the file when broken."""
        folder = self._folder(id_)
        if not folder.is_dir():
            raise StoreError(f"no example {id_!r} in library {self.root}")
        return read_folder(folder).example

    def find_source(self, source_sha256: str) -> list[str]:
        """Ids of the examples decomposed from the scan with this content hash."""
        return catalog.with_source(self._con, source_sha256.lower())

    def info(self) -> dict:
        """Counts per species and tag, number of examples, bytes of example folders."""
        info = catalog.summary(self._con)
        counts = {k: v for k, v in info["tags"].items() if k not in CURVATURE_TAGS}
        for e in self.entries():
            for t in e.tags:
                if t in CURVATURE_TAGS:
                    counts[t] = counts.get(t, 0) + 1
        return {"path": str(self.root), "schema": SCHEMA_VERSION, **info, "tags": dict(sorted(counts.items()))}

    def search(self, query: str | Iterable[str] = "", limit: int | None = None,
               **filters) -> list[_search.SearchHit]:
        """Examples matching ``query`` best first (see ``search.rank``); ``filters`` as ``entries``."""
        return _search.rank(self.entries(**filters), _search.parse_terms(query), limit)

    def new_id(self, prefix: str = "ex") -> str:
        """An unused id ``PREFIX-NNNN`` (one more than the highest number in use with that prefix)."""
        prefix = re.sub(r"[^\w-]", "-", prefix).strip("-_")[:110] or "ex"
        pattern = re.compile(re.escape(prefix) + r"-(\d+)$")
        taken = [int(m.group(1)) for i in self.ids() if (m := pattern.match(i))]
        n = max(taken, default=0) + 1
        while (self.root / "examples" / f"{prefix}-{n:04d}").exists():
            n += 1
        return f"{prefix}-{n:04d}"

    # -- writing -----------------------------------------------------------------------------
    def add(self, example: Example, *, replace: bool = False) -> str:
        """Store ``example`` atomically; ``StoreError`` if its id exists (unless ``replace``)."""
        meta, npz = encode(example)
        return self.put_encoded(example, meta, npz, replace=replace)

    def add_many(self, examples: Iterable[Example], *, replace: bool = False,
                 progress: ProgressFn = no_progress, total: int = 0) -> list[str]:
        """Add each of ``examples`` (each one atomically); returns their ids."""
        done = []
        for ex in examples:
            done.append(self.add(ex, replace=replace))
            progress(len(done), max(total, len(done)), "adding examples")
        return done

    def put_encoded(self, example: Example, meta: bytes, npz: bytes, *, replace: bool = False) -> str:
        """Store ``example`` whose files ``encode`` produced (``meta``, ``npz``) atomically."""
        self._writable()
        target = self._folder(example.id)
        with self._lock():
            exists = target.exists() or catalog.get(self._con, example.id) is not None
            if exists and not replace:
                raise StoreError(f"example {example.id!r} already exists in library {self.root}")
            stage = self.root / ".tmp" / unique("stage-")
            write_folder(stage, meta, npz, self.durable)
            entry = entry_for(example, json.loads(meta), len(meta) + len(npz))
            old, journal = self._swap_in(stage, target, example.id)
            self._commit(lambda: catalog.upsert(self._con, entry))
            if old is not None:
                shutil.rmtree(old)
            journal.unlink()
        return example.id

    def delete(self, id_: str) -> None:
        """Remove example ``id_`` (catalog row first, then its folder)."""
        self._writable()
        target = self._folder(id_)
        with self._lock():
            if not target.exists() and catalog.get(self._con, id_) is None:
                raise StoreError(f"no example {id_!r} in library {self.root}")
            journal = write_journal(self.root / ".tmp", "delete", id_, None, self.durable)
            self._commit(lambda: catalog.remove(self._con, [id_]))
            if target.exists():
                trash = self.root / ".tmp" / unique("trash-")
                os.rename(target, trash)
                shutil.rmtree(trash)
            journal.unlink()

    # -- archives ----------------------------------------------------------------------------
    def export_archive(self, path: str | os.PathLike, progress: ProgressFn = no_progress) -> dict:
        """Write the whole library to one .tar archive (see ``archive``); returns a summary."""
        from .archive import export_archive

        return export_archive(self, Path(path), progress)

    def import_archive(self, path: str | os.PathLike, *, on_conflict: str = "skip",
                       progress: ProgressFn = no_progress):
        """Add every example of archive ``path`` after validating all of them; an ``ImportReport``."""
        from .archive import apply_archive, check_archive

        return apply_archive(self, check_archive(Path(path)), on_conflict, progress)

    # -- internals ---------------------------------------------------------------------------
    def _folder(self, id_: str) -> Path:
        if not isinstance(id_, str) or not valid_id(id_):
            raise StoreError(f"{id_!r} is not a valid example id (letters, digits, '-' and '_')")
        return self.root / "examples" / id_

    def _writable(self) -> None:
        if self.readonly:
            raise StoreError(f"library {self.root} was opened read-only")

    @contextlib.contextmanager
    def _lock(self, finish_crashed: bool = True) -> Iterator[None]:
        """Hold the library's write lock; finish any crashed write found in ``.tmp/`` first."""
        with open(self.root / ".lock", "a+b") as f:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX)
            try:
                if finish_crashed and any((self.root / ".tmp").iterdir()):
                    reconcile(self._con, self.root, full=False)
                yield
            finally:
                fcntl.flock(f.fileno(), fcntl.LOCK_UN)

    def _swap_in(self, stage: Path, target: Path, id_: str) -> tuple[Path | None, Path]:
        """Rename the staged folder to ``target``; returns where the replaced folder went, the journal."""
        tmp = self.root / ".tmp"
        if not target.exists():
            journal = write_journal(tmp, "add", id_, None, self.durable)
            os.rename(stage, target)
            old = None
        else:
            aside = unique("aside-")
            journal = write_journal(tmp, "replace", id_, aside, self.durable)
            if exchange(stage, target):
                old = stage
            else:
                os.rename(target, tmp / aside)
                os.rename(stage, target)
                old = tmp / aside
        if self.durable:
            fsync_path(target.parent)
        return old, journal

    def _commit(self, change) -> None:
        self._con.execute("BEGIN IMMEDIATE")
        try:
            change()
        except BaseException:
            self._con.execute("ROLLBACK")
            raise
        self._con.execute("COMMIT")


def _check_marker(root: Path, create: bool) -> None:
    """Check ``root/library.json`` (or create the library when ``create``); ``InputError`` otherwise."""
    marker = root / "library.json"
    if root.exists() and not root.is_dir():
        raise InputError(f"{root} is a file, not an Arboretum library folder")
    if not marker.exists():
        if root.is_dir() and any(root.iterdir()) and create:
            raise InputError(f"{root} is not an Arboretum library (no library.json) and is not empty")
        if not create:
            what = "is not an Arboretum library (no library.json)" if root.exists() else "does not exist"
            raise InputError(f"library {root} {what}")
        root.mkdir(parents=True, exist_ok=True)
        tmp = root / f".library.json.{os.getpid()}.tmp"
        tmp.write_text(json.dumps({"format": LIBRARY_FORMAT, "schema": SCHEMA_VERSION, "created": now_utc()}) + "\n")
        os.replace(tmp, marker)
        return
    try:
        head = json.loads(marker.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{marker} is not readable JSON ({exc})") from None
    if not isinstance(head, dict) or head.get("format") != LIBRARY_FORMAT:
        raise InputError(f"{root} is not an Arboretum library ({marker} has no '{LIBRARY_FORMAT}' marker)")
    if not isinstance(head.get("schema"), int) or head["schema"] > SCHEMA_VERSION:
        raise InputError(f"library {root} has schema {head.get('schema')!r}, newer than this Arboretum reads ({SCHEMA_VERSION})")
