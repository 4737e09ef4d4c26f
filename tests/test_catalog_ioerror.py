"""An I/O error on the catalog (a full disk, a file-size limit) is no damage: the file stays where it
is. SQLite names such errors by extended codes (SQLITE_IOERR_WRITE), which the check once missed, so
a full disk moved an intact catalog aside as damaged."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from types import SimpleNamespace

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


def _free(monkeypatch, n: int) -> None:
    """The disk under any folder has ``n`` bytes free."""
    usage = SimpleNamespace(total=10 << 30, used=(10 << 30) - n, free=n)
    monkeypatch.setattr(catalog.shutil, "disk_usage", lambda folder: usage)


def test_a_disk_too_full_for_the_shm_file_is_named(monkeypatch):
    """On a disk with 0 bytes free, even reading a WAL catalog fails: SQLite cannot create its -shm file
    and says only "disk I/O error" (SQLITE_IOERR_SHMSIZE, seen on a full 512 KiB tmpfs), which read as
    "cannot be used right now" until session 12."""
    _free(monkeypatch, 0)
    err = catalog.damaged(Path("lib/catalog.sqlite"), _error("SQLITE_IOERR_SHMSIZE", "disk I/O error"))
    assert type(err) is StoreError
    assert str(err) == ('lib/catalog.sqlite: the catalog cannot be used: the disk holding it is full (0 bytes free; '
                        'SQLite says "disk I/O error"); free some space and try again')


@pytest.mark.parametrize("name, free", [("SQLITE_IOERR_SHMSIZE", 5 << 30), ("SQLITE_BUSY", 0)])
def test_room_on_the_disk_or_a_busy_file_is_no_full_disk(monkeypatch, name, free):
    _free(monkeypatch, free)
    err = catalog.damaged(Path("lib/catalog.sqlite"), _error(name, "disk I/O error"))
    assert "cannot be used right now" in str(err) and "full" not in str(err)


def test_free_space_that_cannot_be_asked_is_no_full_disk(monkeypatch, tmp_path):
    def fails(folder):
        raise FileNotFoundError(2, "No such file or directory", str(folder))

    monkeypatch.setattr(catalog.shutil, "disk_usage", fails)
    assert catalog.free_bytes(tmp_path / "gone") is None
    err = catalog.damaged(tmp_path / "gone" / "catalog.sqlite", _error("SQLITE_CANTOPEN", "unable to open"))
    assert "cannot be used right now" in str(err)
