"""An I/O error on the catalog (a full disk, a file-size limit) is no damage: the file stays where it
is. SQLite names such errors by extended codes (SQLITE_IOERR_WRITE), which the check once missed, so
a full disk moved an intact catalog aside as damaged."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from arboretum_library import catalog
from arboretum_library.errors import StoreError


def _error(name: str, text: str) -> sqlite3.DatabaseError:
    exc = sqlite3.OperationalError(text)
    exc.sqlite_errorname = name
    return exc


@pytest.mark.parametrize("name", ["SQLITE_IOERR_WRITE", "SQLITE_IOERR_FSYNC", "SQLITE_IOERR", "SQLITE_FULL",
                                  "SQLITE_BUSY_SNAPSHOT", "SQLITE_READONLY_DBMOVED", "SQLITE_CANTOPEN_ISDIR"])
def test_io_errors_are_not_damage(name):
    err = catalog.damaged(Path("lib/catalog.sqlite"), _error(name, "disk I/O error"))
    assert isinstance(err, StoreError) and not isinstance(err, catalog.CatalogDamaged)
    assert "cannot be used right now" in str(err)


@pytest.mark.parametrize("name", ["SQLITE_CORRUPT", "SQLITE_NOTADB", "SQLITE_CORRUPT_INDEX"])
def test_a_damaged_file_is_damage(name):
    assert isinstance(catalog.damaged(Path("c.sqlite"), _error(name, "malformed")), catalog.CatalogDamaged)
