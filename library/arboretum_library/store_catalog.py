"""An open library's link to its catalog file ``LIB/catalog.sqlite``, which other processes may replace.

A writer holding the lock that finds the catalog missing or damaged rebuilds it from the example folders
under a temporary name and renames it into place (``recovery.open_catalog``), so every other open library
must notice the new file: the link remembers the (device, inode) of the file it connected to and
reconnects when it changed or when SQLite reported damage. A reader (or a writer without the lock) never
rebuilds: it gets ``CatalogDamaged``; a writer's reads rebuild once (taking the lock) and retry.
"""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from . import catalog
from .catalog import CatalogDamaged
from .errors import StoreError
from .recovery import CATALOG, Recovery, open_catalog

T = TypeVar("T")


class CatalogLink:
    """One connection to the catalog of the library at ``root`` (``readonly``: never writes it)."""

    def __init__(self, root: Path, readonly: bool, durable: bool, report: Recovery) -> None:
        self.path = root / CATALOG
        self.root = root
        self.readonly = readonly
        self.durable = durable
        self.report = report
        """Where a rebuild notes why the catalog was rebuilt and where the damaged file went."""
        self._con: sqlite3.Connection | None = None
        self._ident: tuple[int, int] | None = None
        self._broken = False

    @property
    def con(self) -> sqlite3.Connection:
        """The current connection (``sync`` first: another process may have replaced the file)."""
        if self._con is None:
            raise StoreError(f"the catalog of library {self.root} is not open")
        return self._con

    def connect(self, locked: bool = False) -> None:
        """(Re)connect; a writer holding the lock (``locked``) rebuilds a missing or damaged catalog
        (noting it in ``report``), anyone else gets ``CatalogDamaged``."""
        ident = _ident(self.path)
        self.close()
        self._broken = True
        if locked and not self.readonly:
            self._con = open_catalog(self.root, self.durable, self.report)
            ident = _ident(self.path)
        else:
            self._con = catalog.connect(self.path, readonly=self.readonly, durable=self.durable)
        self._ident, self._broken = ident, False

    def sync(self, locked: bool = False) -> None:
        """Reconnect when another process replaced (rebuilt) the catalog file, or after damage."""
        if self._broken or self._con is None or _ident(self.path) != self._ident:
            self.connect(locked)

    def read(self, query: Callable[[sqlite3.Connection], T], rebuild: Callable[[], None] | None) -> T:
        """``query(con)`` on the current catalog. When it is damaged: ``CatalogDamaged`` without
        ``rebuild``, else ``rebuild()`` (a writer takes the lock, which rebuilds it) and retry once."""
        try:
            return self._query(query)
        except CatalogDamaged:
            if rebuild is None:
                raise
        self._broken = True
        rebuild()
        return self._query(query)

    def _query(self, query: Callable[[sqlite3.Connection], T]) -> T:
        try:
            self.sync()
            return query(self.con)
        except sqlite3.DatabaseError as exc:
            raise self.damaged(exc) from None

    def commit(self, change: Callable[[sqlite3.Connection], object]) -> None:
        """``change(con)`` in one write transaction, rolled back when it fails (``catalog.write``)."""
        catalog.write(self.con, change)

    def damaged(self, exc: sqlite3.DatabaseError) -> StoreError:
        """The user-facing error for ``exc`` (see ``catalog.damaged``); a damaged file is reconnected to
        (rebuilt by a writer) on the next ``sync``."""
        err = catalog.damaged(self.path, exc)
        self._broken = self._broken or isinstance(err, CatalogDamaged)
        return err

    def close(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None


def _ident(path: Path) -> tuple[int, int] | None:
    """(device, inode) of ``path``, None when missing: tells whether another process replaced the file."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_dev, st.st_ino
