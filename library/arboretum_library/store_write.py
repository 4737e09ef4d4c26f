"""How a write to the example library is staged, journaled and committed: the writing half of
``store.Library``, which inherits these methods from ``LibraryWrites`` (see ``store`` for the layout).

Every write holds the write lock (``store_lock``; re-entrant, so ``Library.locked()`` can wrap several).
``add``/``put_encoded`` write the example's files to a fresh ``LIB/.tmp/stage-*`` folder, then a journal
in ``.tmp/`` naming what is about to happen (``recovery.write_journal``), rename the staged folder whole
into ``examples/`` (a replaced folder is exchanged with it, or moved aside first), commit its catalog
row and remove the journal. ``add_new`` journals its whole group before staging any of it and commits
all the rows in one transaction, so readers see none or all of them; a failure takes the group back
(``recovery.take_back``). ``delete`` journals, removes the catalog row, then the folder.
After a crash the next writer finishes or undoes the write from its journal, and discards any staged
folder (``recovery.reconcile``). A write the disk refuses raises ``DiskError`` saying what became of it
(``folders.disk_errors``).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sqlite3
from collections.abc import Iterable
from dataclasses import replace as with_fields
from pathlib import Path
from typing import TYPE_CHECKING

from . import catalog
from .errors import StoreError
from .folders import disk_errors, encode, entry_for, exchange, fsync_path, holds, write_folder
from .model import Example
from .progress import ProgressFn, no_progress
from .recovery import take_back, unique, write_journal
from .store_catalog import CatalogLink

__all__ = ["LibraryWrites"]


class LibraryWrites:
    """The writing methods of ``store.Library`` (its only user): add, replace and delete examples."""

    root: Path
    readonly: bool
    durable: bool
    _catalog: CatalogLink

    if TYPE_CHECKING:  # provided by ``store.Library``
        @property
        def _con(self) -> sqlite3.Connection: ...
        def _lock(self) -> contextlib.AbstractContextManager[None]: ...
        def _folder(self, id_: str) -> Path: ...
        def _no_example(self, id_: str) -> StoreError: ...
        def _free_ids(self, prefix: str, count: int) -> list[str]: ...

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

    # -- the write lock ----------------------------------------------------------------------
    def _writable(self) -> None:
        if self.readonly:
            raise StoreError(f"library {self.root} was opened read-only")

    def locked(self) -> contextlib.AbstractContextManager[None]:
        """Hold the write lock over several steps (check, then write) that another writer must not
        interleave; the store's own writes inside take it again (re-entrant for this thread)."""
        self._writable()
        return self._lock()
