"""The SQLite catalog of an example library: one row per example, an index over what search needs.

The catalog is derived data: every row can be rebuilt from the example folder's ``meta.json`` (the
store does so when it finds a folder without a row). It runs in WAL mode so that reader processes go on
reading while one writer commits. Write transactions are ``BEGIN IMMEDIATE`` ... ``COMMIT``.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from .errors import StoreError
from .model import Descriptors

SCHEMA_VERSION = 1
"""``PRAGMA user_version`` of the catalog (and schema of meta.json, library.json)."""

BUSY_TIMEOUT_MS = 30_000

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


def connect(path: Path, *, readonly: bool, durable: bool) -> sqlite3.Connection:
    """Open the catalog at ``path`` (autocommit; explicit transactions). Creates it unless ``readonly``."""
    try:
        if readonly:
            con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, isolation_level=None,
                                  timeout=BUSY_TIMEOUT_MS / 1000)
        else:
            con = sqlite3.connect(path, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
        con.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        version = con.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:
            con.close()
            raise StoreError(f"{path}: catalog schema {version} is newer than this Arboretum reads ({SCHEMA_VERSION})")
        if not readonly:
            con.execute("PRAGMA journal_mode = WAL")
            con.execute(f"PRAGMA synchronous = {'FULL' if durable else 'NORMAL'}")
            con.execute("PRAGMA foreign_keys = ON")
            if version < SCHEMA_VERSION:
                con.executescript(_SCHEMA)
                con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{path}: cannot open the catalog ({exc})") from None
    return con


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
    for tag in tags:
        where.append("id IN (SELECT id FROM tags WHERE tag = ?)")
        args.append(tag.lower())
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
