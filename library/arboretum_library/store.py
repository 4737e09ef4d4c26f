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
reconnects when another process did (see ``store_catalog``). How a write is staged, journaled and
committed (``add``, ``add_new``, ``put_encoded``, ``delete``, ``locked``): ``store_write``, whose
``LibraryWrites`` ``Library`` inherits. Crash recovery: ``recovery``.

A write the disk refuses (full, read-only, an I/O error) raises ``DiskError``, one line naming the
library, the cause and what became of the write ("nothing was stored"); a library whose folder vanished
while open (deleted, moved, unmounted) raises ``LibraryGone`` and is never recreated by a write.
"""

from __future__ import annotations

import contextlib
import os
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
    free_ids,
    read_folder,
    read_provenance,
    read_revision,
    valid_id,
)
from .model import Example, Provenance
from .progress import ProgressFn, no_progress
from .recovery import Recovery, reconcile
from .store_catalog import CatalogLink
from .store_lock import LOCK_TIMEOUT_S, LibraryBusy, LibraryGone, WriteLock, check_present
from .store_write import LibraryWrites

__all__ = ["CatalogDamaged", "DiskError", "Library", "LibraryBusy", "LibraryGone", "LOCK_TIMEOUT_S"]

T = TypeVar("T")


class Library(LibraryWrites):
    """An open example library. Create with ``Library.open``; close with ``close()`` or ``with``.

    Opening, reading and the lock are here; ``add``, ``add_many``, ``add_new``, ``put_encoded``,
    ``delete`` and ``locked`` come from ``store_write.LibraryWrites``."""

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

    def find_content(self, hashes: Iterable[str], source: str, species: str) -> dict[str, str]:
        """For each of ``hashes`` (SHA-256 of an arrays.npz, ``Entry.content_sha256``) stored under this
        source name and species, the lowest id holding it (one catalog query, no rows loaded)."""
        return self._read(lambda con: catalog.with_content(con, [h.lower() for h in hashes], source, species))

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
