"""The example library on disk: whole example folders plus a SQLite catalog (see docs/library.md).

Layout::

    LIB/library.json            format marker and schema version
    LIB/catalog.sqlite          the index (WAL mode; derived from the folders, rebuilt if lost or damaged)
    LIB/examples/<id>/          meta.json + arrays.npz of one example
    LIB/.tmp/                   staging folders and write journals (empty when no write is under way)
    LIB/.lock                   held (flock) by a process while it writes
    LIB/quarantine/             broken folders found when reconciling

A ``Library`` holds a path and one SQLite connection; use one per thread. Any number of processes can
read while one writes; writers take turns through the lock file, each waiting at most ``lock_timeout``
seconds for it (then ``LibraryBusy``; see ``store_lock``). A reader finding the catalog missing or
damaged raises ``CatalogDamaged``; a writer rebuilds it from the folders, and every open library
reconnects when another process did (see ``store_catalog``). Crash recovery: ``recovery``.

A write the disk refuses (full, read-only, an I/O error) raises ``DiskError``, one line naming the
library, the cause and what became of the write ("nothing was stored"); a library whose folder vanished
while open (deleted, moved, unmounted) raises ``LibraryGone`` and is never recreated by a write.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sqlite3
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace as with_fields
from pathlib import Path
from typing import TypeVar

import numpy as np

from . import catalog
from . import search as _search
from .catalog import SCHEMA_VERSION, CatalogDamaged, Entry
from .descriptors import CURVATURE_TAGS, relative_curvature_tags, tercile_bounds
from .errors import StoreError
from .folders import (
    DiskError,
    check_marker,
    disk_errors,
    encode,
    entry_for,
    exchange,
    free_ids,
    fsync_path,
    holds,
    read_folder,
    read_provenance,
    read_revision,
    valid_id,
    write_folder,
)
from .model import Example, Provenance
from .progress import ProgressFn, no_progress
from .recovery import Recovery, reconcile, take_back, unique, write_journal
from .store_catalog import CatalogLink
from .store_lock import LOCK_TIMEOUT_S, LibraryBusy, LibraryGone, WriteLock, check_present

__all__ = ["CatalogDamaged", "DiskError", "Library", "LibraryBusy", "LibraryGone", "LOCK_TIMEOUT_S"]

T = TypeVar("T")


class Library:
    """An open example library. Create with ``Library.open``; close with ``close()`` or ``with``."""

    def __init__(self, root: Path, readonly: bool, durable: bool, lock_timeout: float | None = LOCK_TIMEOUT_S,
                 on_wait: Callable[[str], None] | None = None) -> None:
        self.root = root
        self.readonly = readonly
        self.durable = durable
        self.lock_timeout = lock_timeout
        """Seconds a write waits for another process's lock (None: as long as it takes)."""
        self.on_wait = on_wait
        """Called with a message when a write has to wait for the lock (e.g. to tell a CLI user)."""
        self.recovered = Recovery()
        """What reconciling did when this (writing) library was opened."""
        self._catalog = CatalogLink(root, readonly, durable, self.recovered)
        self._write_lock = WriteLock(root)

    # -- opening -----------------------------------------------------------------------------
    @classmethod
    def open(cls, path: str | os.PathLike, create: bool = False, *, readonly: bool = False,
             fsync: bool = True, lock_timeout: float | None = LOCK_TIMEOUT_S,
             on_wait: Callable[[str], None] | None = None) -> Library:
        """Open the library at ``path`` (``create``: make it if missing). ``InputError`` if it is not one.

        ``readonly`` opens never write or reconcile (``CatalogDamaged`` when the catalog is missing or
        damaged); a writing open rebuilds such a catalog from the folders. ``fsync`` makes every write
        durable on power loss. ``lock_timeout``, ``on_wait``: see the attributes.
        """
        root = Path(path)
        check_marker(root, create and not readonly)
        lib = cls(root, readonly, fsync, lock_timeout, on_wait)
        if readonly:
            lib._catalog.connect()
            return lib
        with disk_errors(root, "it cannot be opened to write"):
            try:
                for sub in ("examples", ".tmp"):
                    (root / sub).mkdir(exist_ok=True)
                with lib._lock(finish_crashed=False):
                    lib._catalog.connect(locked=True)
                    lib.recovered.merge(reconcile(lib._con, root, full=True))
            except BaseException:
                lib.close()
                raise
        return lib

    @classmethod
    def open_reading(cls, path: str | os.PathLike, *, lock_timeout: float | None = LOCK_TIMEOUT_S,
                     on_wait: Callable[[str], None] | None = None) -> Library:
        """Open the library at ``path`` to read it: read-only, or as a writer (``lock_timeout``,
        ``on_wait``) when its catalog is missing or damaged, which rebuilds it from the example folders
        (``recovered.catalog_problem`` then says why). ``StoreError`` naming the catalog and the reason
        when this process cannot write the library to rebuild it."""
        try:
            return cls.open(path, readonly=True)
        except CatalogDamaged as damaged:
            try:
                return cls.open(path, lock_timeout=lock_timeout, on_wait=on_wait)
            except OSError as why:
                where = f": {why.filename}" if why.filename else ""
                because = getattr(why, "cause", "") or f"{why.strerror or why}{where}"
                raise StoreError(f"{damaged}, but this process cannot write the library ({because})") from None

    def close(self) -> None:
        self._catalog.close()

    def __enter__(self) -> Library:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- reading -----------------------------------------------------------------------------
    def ids(self) -> list[str]:
        """Every example id, sorted."""
        return self._read(catalog.ids)

    def __len__(self) -> int:
        return self._read(lambda con: con.execute("SELECT COUNT(*) FROM examples").fetchone()[0])

    def __contains__(self, id_: object) -> bool:
        return isinstance(id_, str) and self._read(lambda con: catalog.get(con, id_)) is not None

    def entry(self, id_: str) -> Entry:
        """The catalog row of ``id_`` (no arrays loaded), with the library's 'straight'/'curved' (``entries``)."""
        e = self._read(lambda con: catalog.get(con, id_))
        if e is None:
            raise self._no_example(id_)
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
        rows = self._relative(self._read(lambda con: catalog.select(con, **filters)))
        return [e for e in rows if all(t in e.tags for t in want if t in CURVATURE_TAGS)]

    def _relative(self, rows: list[Entry]) -> list[Entry]:
        """``rows`` with 'straight'/'curved' decided by the terciles of their species in the library."""
        if not rows:
            return rows
        by_species = self._read(catalog.curvature_by_species)
        bounds = {k: tercile_bounds(np.array(v)) for k, v in by_species.items()}
        return [with_fields(e, tags=relative_curvature_tags(e.tags, e.descriptors.curvature, bounds.get(e.species)))
                for e in rows]

    def get(self, id_: str) -> Example:
        """Load example ``id_`` whole. ``StoreError`` names the id when missing, the file when broken."""
        folder = self._folder(id_)
        if not folder.is_dir():
            raise self._no_example(id_)
        return read_folder(folder).example

    def provenance(self, id_: str) -> Provenance:
        """Where example ``id_`` came from, read from its meta.json alone (no arrays loaded or checked:
        about 20 times cheaper than ``get``). ``StoreError`` names the id when missing."""
        try:
            return read_provenance(self._folder(id_))
        except (FileNotFoundError, NotADirectoryError):
            raise self._no_example(id_) from None
        except OSError as exc:
            raise StoreError(f"cannot read {exc.filename}: {exc.strerror}") from None

    def revision(self, id_: str) -> str:
        """A token that changes whenever example ``id_`` is replaced (SHA-256 of its meta.json, which holds
        the arrays' SHA-256): cheap to check against a cached copy. ``StoreError`` when it is missing."""
        folder = self._folder(id_)
        try:
            return read_revision(folder)
        except (FileNotFoundError, NotADirectoryError):
            raise self._no_example(id_) from None
        except OSError as exc:
            raise StoreError(f"cannot read {exc.filename}: {exc.strerror}") from None

    def find_source(self, source_sha256: str) -> list[str]:
        """Ids of the examples decomposed from the scan with this content hash."""
        return self._read(lambda con: catalog.with_source(con, source_sha256.lower()))

    def info(self) -> dict:
        """Counts per species and tag, number of examples, bytes of example folders."""
        info = self._read(catalog.summary)
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
        """An unused id ``PREFIX-NNNN`` (one more than the highest number in use with that prefix).

        Another process may take it before you ``add`` it: to store new examples, use ``add_new``.
        """
        return self._free_ids(prefix, 1)[0]

    def _free_ids(self, prefix: str, count: int) -> list[str]:
        return free_ids(self.ids(), self.root / "examples", prefix, count)

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

    def add_new(self, examples: Iterable[Example], prefix: str = "ex") -> list[Example]:
        """Store ``examples`` under fresh ids ``PREFIX-NNNN`` picked while holding the write lock (so two
        processes never pick the same), all or none: their catalog rows are committed together, last, so
        readers see none or all of them; a failure (or Ctrl-C) deletes the folders already in place, and a
        crash (or a failure that cannot delete them) leaves the group journal, with which the next writer
        does. Returns them renamed. On a full disk: ``DiskError`` "library LIB: no space left on device
        (ENOSPC); nothing was stored"."""
        self._writable()
        todo = list(examples)
        with self._lock():
            ids = self._free_ids(prefix, len(todo))
            out = [with_fields(ex, id=i) for ex, i in zip(todo, ids, strict=True)]
            with disk_errors(self.root, "nothing was stored"):
                group = write_journal(self.root / ".tmp", "add_group", "", None, self.durable, ids=ids)
            staged: list[Path] = []
            undone = False
            left = "nothing was stored (the next write to the library removes what is left)"
            with disk_errors(self.root, lambda: "nothing was stored" if undone else left):
                try:
                    self._add_group(out, staged)
                except BaseException:
                    if undone := take_back(self._con, self.root, ids, staged):
                        group.unlink(missing_ok=True)
                    raise
            group.unlink()  # stored; and durably so, or a power loss could bring the journal back, and with
            if self.durable:  # it the next writer would take the run back
                with contextlib.suppress(OSError):
                    fsync_path(group.parent)
        return out

    def _add_group(self, examples: list[Example], staged: list[Path]) -> None:
        """Stage every example in ``.tmp/`` (listing the folders in ``staged``), rename each into
        ``examples/``, then commit all their rows in one transaction: readers see none, then all."""
        entries = []
        for ex in examples:
            meta, npz = encode(ex)
            staged.append(self.root / ".tmp" / unique("stage-"))
            write_folder(staged[-1], meta, npz, self.durable)
            entries.append(entry_for(ex, json.loads(meta), len(meta) + len(npz)))
        for ex, stage in zip(examples, staged, strict=True):
            os.rename(stage, self._folder(ex.id))
        if self.durable:
            fsync_path(self.root / "examples")
        self._catalog.commit(lambda con: [catalog.upsert(con, e) for e in entries])

    def put_encoded(self, example: Example, meta: bytes, npz: bytes, *, replace: bool = False) -> str:
        """Store ``example`` whose files ``encode`` produced (``meta``, ``npz``) atomically."""
        self._writable()
        self._folder(example.id)
        with self._lock():
            stage = self.root / ".tmp" / unique("stage-")
            with disk_errors(self.root, lambda: f"example {example.id!r} was not stored" if not placed else
                             f"the next write to the library finishes storing example {example.id!r}"):
                try:
                    self._put(example, meta, npz, stage, replace=replace)
                except BaseException:
                    with contextlib.suppress(OSError):  # (nothing left there is needed, see recovery)
                        shutil.rmtree(stage)
                    placed = holds(self._folder(example.id), meta)  # its journal: the next writer indexes it
                    raise
        return example.id

    def _put(self, example: Example, meta: bytes, npz: bytes, stage: Path, *, replace: bool) -> None:
        """``put_encoded`` with the lock held, staging the files in the new folder ``stage``."""
        target = self._folder(example.id)
        exists = target.exists() or catalog.get(self._con, example.id) is not None
        if exists and not replace:
            raise StoreError(f"example {example.id!r} already exists in library {self.root}")
        write_folder(stage, meta, npz, self.durable)
        entry = entry_for(example, json.loads(meta), len(meta) + len(npz))
        old, journal = self._swap_in(stage, target, example.id)
        self._catalog.commit(lambda con: catalog.upsert(con, entry))
        if old is not None:
            shutil.rmtree(old)
        journal.unlink()

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

    def delete(self, id_: str) -> None:
        """Remove example ``id_`` (catalog row first, then its folder)."""
        self._writable()
        target = self._folder(id_)
        with self._lock():
            if not target.exists() and catalog.get(self._con, id_) is None:
                raise self._no_example(id_)
            self._delete(id_)

    def _delete(self, id_: str) -> None:
        """``delete`` with the lock held."""
        target = self._folder(id_)
        with disk_errors(self.root, f"example {id_!r} was not deleted"):
            journal = write_journal(self.root / ".tmp", "delete", id_, None, self.durable)
        with disk_errors(self.root, f"the next write to the library finishes deleting example {id_!r}"):
            self._catalog.commit(lambda con: catalog.remove(con, [id_]))
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

    def _no_example(self, id_: str) -> StoreError:
        """The error for a missing example: ``LibraryGone`` raised instead when the whole library is."""
        check_present(self.root)
        return StoreError(f"no example {id_!r} in library {self.root}")

    def _writable(self) -> None:
        if self.readonly:
            raise StoreError(f"library {self.root} was opened read-only")

    def locked(self) -> contextlib.AbstractContextManager[None]:
        """Hold the write lock over several steps (check, then write) that another writer must not
        interleave; the store's own writes inside take it again (re-entrant for this thread)."""
        self._writable()
        return self._lock()

    @contextlib.contextmanager
    def _lock(self, finish_crashed: bool = True) -> Iterator[None]:
        """Hold the write lock (see ``store_lock``); then reconnect if the catalog was replaced or damaged
        (rebuilding it) and finish any crashed write found in ``.tmp/``. Re-entrant for this thread."""
        if self._write_lock.held_here():
            yield
            return
        with self._write_lock.hold(self.lock_timeout, self.on_wait):
            try:
                if finish_crashed:
                    self._catalog.sync(locked=True)
                    if any((self.root / ".tmp").iterdir()):
                        reconcile(self._con, self.root, full=False)
                yield
            except sqlite3.DatabaseError as exc:
                raise self._catalog.damaged(exc) from None

    # -- the catalog connection (see ``store_catalog``) ---------------------------------------
    @property
    def _con(self) -> sqlite3.Connection:
        return self._catalog.con

    def _read(self, query: Callable[[sqlite3.Connection], T]) -> T:
        """``query(con)`` on a current catalog; a writer rebuilds a damaged catalog once and retries.
        ``LibraryGone`` when the catalog went with the whole library."""
        try:
            return self._catalog.read(query, None if self.readonly else self._rebuild_catalog)
        except CatalogDamaged:
            check_present(self.root)
            raise

    def _rebuild_catalog(self) -> None:
        with self._lock():  # taking the lock reconnects, rebuilding a damaged catalog
            pass
