"""The SQLite catalog of an example library: one row per example, an index over what search needs.

The catalog is derived data: every row can be rebuilt from the example folder's ``meta.json`` (the
store does so when it finds a folder without a row, and rebuilds the whole file when ``connect`` finds it
missing or damaged: ``CatalogDamaged``). It runs in WAL mode so that reader processes go on
reading while one writer commits. Write transactions are ``BEGIN IMMEDIATE`` ... ``COMMIT``.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import sqlite3
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from .errors import StoreError
from .model import Descriptors

SCHEMA_VERSION = 1
"""``PRAGMA user_version`` of the catalog (and schema of meta.json, library.json)."""

BUSY_TIMEOUT_MS = 30_000
_MAGIC = b"SQLite format 3\x00"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS examples (
    id TEXT PRIMARY KEY,
    species TEXT NOT NULL,
    source TEXT NOT NULL,
    source_sha256 TEXT NOT NULL,
    tags TEXT NOT NULL,
    lobe_count INTEGER NOT NULL,
    curvature REAL NOT NULL,
    length REAL NOT NULL,
    spread REAL NOT NULL,
    height REAL NOT NULL,
    content_sha256 TEXT NOT NULL,
    size_bytes INTEGER NOT NULL,
    created TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS examples_source ON examples (source_sha256);
CREATE INDEX IF NOT EXISTS examples_species ON examples (species);
CREATE TABLE IF NOT EXISTS tags (
    tag TEXT NOT NULL,
    id TEXT NOT NULL REFERENCES examples (id) ON DELETE CASCADE,
    PRIMARY KEY (tag, id)
) WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS tags_id ON tags (id);
"""

_COLUMNS = (
    "id, species, source, source_sha256, tags, lobe_count, curvature, length, spread, height, "
    "content_sha256, size_bytes, created"
)


@dataclass(frozen=True)
class Entry:
    """One catalog row: what listing and search need without loading any array."""

    id: str
    species: str
    source: str
    source_sha256: str
    tags: tuple[str, ...]
    descriptors: Descriptors
    content_sha256: str
    """Hex SHA-256 of the example's arrays.npz."""
    size_bytes: int
    """Bytes on disk of meta.json + arrays.npz."""
    created: str
    """UTC time the example was added, ISO 8601."""


class CatalogDamaged(StoreError):
    """The catalog file is missing or damaged. A writer rebuilds it from the example folders."""

    def __init__(self, path: Path, reason: str, hint: str = "") -> None:
        self.path = path
        self.reason = reason
        hint = hint or ("opening the library for writing rebuilds it from the example folders "
                        "(the damaged file is kept aside)")
        super().__init__(f"the catalog {path} {reason}; {hint}")


def connect(path: Path, *, readonly: bool, durable: bool, check: bool = True) -> sqlite3.Connection:
    """Open the existing catalog at ``path`` and ``check`` it (autocommit; explicit transactions).

    ``CatalogDamaged`` when it is missing, not a database, lacks the tables or fails ``quick_check``;
    ``StoreError`` when its schema is newer than this code. Check with ``readonly`` first: a writing
    connection may checkpoint a WAL into a damaged file (see ``recovery.open_catalog``).
    """
    try:
        with open(path, "rb") as f:
            head = f.read(len(_MAGIC))
    except FileNotFoundError:
        raise CatalogDamaged(path, "is missing") from None
    except OSError as exc:
        raise StoreError(f"{path}: cannot read the catalog ({exc.strerror or exc})") from None
    if head != _MAGIC:
        raise CatalogDamaged(path, "is empty" if not head else "is damaged (not an SQLite database)")
    try:
        if readonly:
            con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, isolation_level=None,
                                  timeout=BUSY_TIMEOUT_MS / 1000)
        else:
            con = sqlite3.connect(path, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{path}: cannot open the catalog ({exc})") from None
    try:
        _check(con, path, full=check)
        if not readonly:
            con.execute("PRAGMA journal_mode = WAL")
            con.execute(f"PRAGMA synchronous = {'FULL' if durable else 'NORMAL'}")
            con.execute("PRAGMA foreign_keys = ON")
    except BaseException as exc:
        con.close()
        if isinstance(exc, sqlite3.DatabaseError):
            raise damaged(path, exc) from None
        raise
    return con


def _check(con: sqlite3.Connection, path: Path, full: bool) -> None:
    """Raise ``CatalogDamaged`` unless ``con`` is a whole catalog of this schema (``full``: also run
    SQLite's ``quick_check``, which reads the whole file: ~ms per thousand examples)."""
    con.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
    version = con.execute("PRAGMA user_version").fetchone()[0]
    if version > SCHEMA_VERSION:
        raise StoreError(f"{path}: catalog schema {version} is newer than this Arboretum reads ({SCHEMA_VERSION})")
    columns = [r[1] for r in con.execute("PRAGMA table_info(examples)")]
    tag_columns = [r[1] for r in con.execute("PRAGMA table_info(tags)")]
    if version < SCHEMA_VERSION or columns != _COLUMNS.split(", ") or tag_columns != ["tag", "id"]:
        raise CatalogDamaged(path, "is damaged (its tables are missing or incomplete)")
    if not full:
        return
    problems = [r[0] for r in con.execute("PRAGMA quick_check(3)")]
    if problems != ["ok"]:
        raise CatalogDamaged(path, f"is damaged ({'; '.join(problems)[:200]})")


def create(path: Path) -> None:
    """Write an empty catalog (WAL mode, the schema) at ``path``, which must not exist."""
    con = sqlite3.connect(path, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
    try:
        con.execute("PRAGMA journal_mode = WAL")
        con.executescript(_SCHEMA)
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    finally:
        con.close()


_NOT_DAMAGE = {"SQLITE_BUSY", "SQLITE_LOCKED", "SQLITE_IOERR", "SQLITE_CANTOPEN", "SQLITE_READONLY",
               "SQLITE_FULL", "SQLITE_NOMEM", "SQLITE_PERM", "SQLITE_INTERRUPT"}


def damaged(path: Path, exc: sqlite3.DatabaseError) -> StoreError:
    """The user-facing error for ``exc`` raised by SQLite on the catalog at ``path``: ``CatalogDamaged``
    when the file is damaged, a plain ``StoreError`` when it is busy or cannot be read."""
    name = getattr(exc, "sqlite_errorname", "")
    primary = "_".join(name.split("_")[:2])  # SQLITE_IOERR_WRITE (a full disk, a file-size limit) is an I/O error
    if primary in _NOT_DAMAGE or (not name and "locked" in str(exc)):
        free = free_bytes(path.parent) if primary in _SPACE else None
        if free is not None and free < LOW_SPACE:
            return StoreError(f"{path}: the catalog cannot be used: the disk holding it is full ({free:,} bytes "
                              f"free; SQLite says \"{exc}\"); free some space and try again")
        return StoreError(f"{path}: the catalog cannot be used right now ({exc})")
    return CatalogDamaged(path, f"is damaged ({exc})")


_SPACE = {"SQLITE_IOERR", "SQLITE_CANTOPEN", "SQLITE_FULL"}
"""SQLite's words for what a full disk does: it cannot write (FULL, IOERR_WRITE), or cannot create the
``-shm`` file that WAL mode needs even to read (IOERR_SHMSIZE on a disk with 0 bytes free)."""
LOW_SPACE = 1 << 20
"""Below this many free bytes, such an error is put down to a full disk (an -shm file takes 32 KiB)."""


def free_bytes(folder: Path) -> int | None:
    """Free bytes on the disk holding ``folder`` (None when that cannot be asked)."""
    try:
        return int(shutil.disk_usage(folder).free)
    except OSError:
        return None


def write(con: sqlite3.Connection, change: Callable[[sqlite3.Connection], object]) -> None:
    """``change(con)`` in one write transaction (``BEGIN IMMEDIATE``), rolled back when it fails (a
    COMMIT failing on a full disk too, which SQLite may leave open: the next write could not begin)."""
    con.execute("BEGIN IMMEDIATE")
    try:
        change(con)
        con.execute("COMMIT")
    except BaseException:
        if con.in_transaction:
            with contextlib.suppress(sqlite3.Error):
                con.execute("ROLLBACK")
        raise


def upsert(con: sqlite3.Connection, e: Entry) -> None:
    """Insert or replace ``e`` and its tags (call inside a transaction)."""
    d = e.descriptors
    con.execute("DELETE FROM tags WHERE id = ?", (e.id,))
    con.execute(
        f"INSERT OR REPLACE INTO examples ({_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        (e.id, e.species, e.source, e.source_sha256, " ".join(e.tags), d.lobe_count, d.curvature,
         d.length, d.spread, d.height, e.content_sha256, e.size_bytes, e.created),
    )
    con.executemany("INSERT INTO tags (tag, id) VALUES (?, ?)", [(t, e.id) for t in e.tags])


def remove(con: sqlite3.Connection, ids: Iterable[str]) -> None:
    """Delete the rows of ``ids`` and their tags (call inside a transaction)."""
    rows = [(i,) for i in ids]
    con.executemany("DELETE FROM tags WHERE id = ?", rows)
    con.executemany("DELETE FROM examples WHERE id = ?", rows)


def _entry(row: tuple) -> Entry:
    (id_, species, source, source_sha, tags, lobes, curv, length, spread, height, sha, size, created) = row
    d = Descriptors(float(curv), int(lobes), float(length), float(spread), float(height))
    return Entry(id_, species, source, source_sha, tuple(tags.split()), d, sha, int(size), created)


def ids(con: sqlite3.Connection) -> list[str]:
    """Every id, sorted."""
    return [r[0] for r in con.execute("SELECT id FROM examples ORDER BY id")]


def get(con: sqlite3.Connection, id_: str) -> Entry | None:
    """The row of ``id_``, or None."""
    row = con.execute(f"SELECT {_COLUMNS} FROM examples WHERE id = ?", (id_,)).fetchone()
    return _entry(row) if row else None


def select(con: sqlite3.Connection, *, species: str | None = None, tags: Iterable[str] = (),
           min_lobes: int | None = None, max_lobes: int | None = None,
           min_curvature: float | None = None, max_curvature: float | None = None) -> list[Entry]:
    """Rows passing every given filter (species equal, all ``tags`` present, ranges inclusive), by id."""
    where, args = [], []
    if species is not None:
        where.append("species = ?")
        args.append(species.lower())
    wanted = sorted({t.lower() for t in tags})
    if wanted:  # one sub-query for any number of tags (one per tag overflows SQLite's expression depth)
        where.append("id IN (SELECT id FROM tags WHERE tag IN (SELECT value FROM json_each(?)) "
                     "GROUP BY id HAVING COUNT(*) = ?)")
        args += [json.dumps(wanted), len(wanted)]
    for column, op, value in (("lobe_count", ">=", min_lobes), ("lobe_count", "<=", max_lobes),
                              ("curvature", ">=", min_curvature), ("curvature", "<=", max_curvature)):
        if value is not None:
            where.append(f"{column} {op} ?")
            args.append(value)
    sql = f"SELECT {_COLUMNS} FROM examples"
    if where:
        sql += " WHERE " + " AND ".join(where)
    return [_entry(r) for r in con.execute(sql + " ORDER BY id", args)]


def with_source(con: sqlite3.Connection, source_sha256: str) -> list[str]:
    """Ids of examples decomposed from the scan whose bytes hash to ``source_sha256``."""
    rows = con.execute("SELECT id FROM examples WHERE source_sha256 = ? ORDER BY id", (source_sha256,))
    return [r[0] for r in rows]


def with_content(con: sqlite3.Connection, hashes: Iterable[str], source: str, species: str) -> dict[str, str]:
    """For each of ``hashes`` (``content_sha256``) held by an example of ``source`` and ``species``, the
    lowest such id. One query; the species index narrows it (1.5 ms for 10,000 rows of one species)."""
    rows = con.execute("SELECT content_sha256, MIN(id) FROM examples WHERE species = ? AND source = ? AND "
                       "content_sha256 IN (SELECT value FROM json_each(?)) GROUP BY content_sha256",
                       (species.lower(), source, json.dumps(sorted(set(hashes)))))
    return dict(rows.fetchall())


def summary(con: sqlite3.Connection) -> dict:
    """Counts: examples, per species, per tag; total bytes of example folders."""
    n, size = con.execute("SELECT COUNT(*), COALESCE(SUM(size_bytes), 0) FROM examples").fetchone()
    species = dict(con.execute("SELECT species, COUNT(*) FROM examples GROUP BY species ORDER BY species"))
    tags = dict(con.execute("SELECT tag, COUNT(*) FROM tags GROUP BY tag ORDER BY tag"))
    return {"examples": int(n), "size_bytes": int(size), "species": species, "tags": tags}


def curvature_by_species(con: sqlite3.Connection) -> dict[str, list[float]]:
    """Main-branch curvatures of every example, per species."""
    out: dict[str, list[float]] = {}
    for species, curvature in con.execute("SELECT species, curvature FROM examples"):
        out.setdefault(species, []).append(float(curvature))
    return out
