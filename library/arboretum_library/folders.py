"""One example on disk: a folder holding ``meta.json`` and ``arrays.npz``, written whole or not at all.

``write_folder`` fills a fresh staging folder (optionally fsynced); the store then renames the whole
folder into place, so a reader never sees half of one. ``read_folder`` checks everything it reads (JSON,
format marker, schema, SHA-256 of the arrays, the record's own validation) and names the broken file.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import hashlib
import json
import os
import re
import sqlite3
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .catalog import SCHEMA_VERSION, Entry
from .codec import arrays_to_npz, flatten, npz_to_arrays, unflatten
from .errors import InputError, StoreError, ValidationError
from .model import Example, Provenance

META = "meta.json"
ARRAYS = "arrays.npz"
EXAMPLE_FORMAT = "arboretum-example"
LIBRARY_FORMAT = "arboretum-library"


@dataclass(frozen=True)
class Folder:
    """An example folder that was read and checked."""

    example: Example
    entry: Entry
    """The catalog row describing it."""


def valid_id(id_: str) -> bool:
    """True when ``id_`` is a legal example id (the rule of ``Example.id``), so a safe folder name."""
    return bool(id_) and len(id_) <= 128 and all(c.isalnum() or c in "-_" for c in id_)


def now_utc() -> str:
    """The current UTC time, ISO 8601 with a Z, to the second."""
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def fsync_path(path: Path) -> None:
    """fsync a file or a directory (so a rename or a new entry in it is durable)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_bytes(path: Path, data: bytes, durable: bool) -> None:
    """Create ``path`` with ``data``; fsync it when ``durable``."""
    with open(path, "xb") as f:
        f.write(data)
        if durable:
            f.flush()
            os.fsync(f.fileno())


def encode(example: Example, created: str | None = None) -> tuple[bytes, bytes]:
    """The bytes of ``meta.json`` and ``arrays.npz`` for ``example``."""
    meta, arrays = flatten(example)
    npz = arrays_to_npz(arrays)
    head = {
        "format": EXAMPLE_FORMAT,
        "schema": SCHEMA_VERSION,
        "id": example.id,
        "created": created or now_utc(),
        "arrays_sha256": hashlib.sha256(npz).hexdigest(),
        "arrays_bytes": len(npz),
        "example": meta,
    }
    return (json.dumps(head, indent=1, sort_keys=True) + "\n").encode(), npz


def write_folder(folder: Path, meta_bytes: bytes, npz_bytes: bytes, durable: bool) -> None:
    """Create ``folder`` holding the two files (fsynced with the folder itself when ``durable``)."""
    folder.mkdir()
    write_bytes(folder / ARRAYS, npz_bytes, durable)
    write_bytes(folder / META, meta_bytes, durable)
    if durable:
        fsync_path(folder)


def entry_for(example: Example, head: dict[str, Any], size_bytes: int) -> Entry:
    """The catalog row of ``example`` whose meta.json header is ``head``."""
    p = example.provenance
    return Entry(example.id, p.species.lower(), p.source, p.source_sha256, example.tags,
                 example.descriptors, head["arrays_sha256"], size_bytes, head["created"])


def _head(meta_bytes: bytes, where: str) -> dict[str, Any]:
    """The checked header of an example's meta.json; ``ValidationError`` says what is wrong."""
    try:
        head = json.loads(meta_bytes.decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValidationError(f"{where}/{META} is not valid JSON ({exc})") from None
    if not isinstance(head, dict) or head.get("format") != EXAMPLE_FORMAT:
        raise ValidationError(f"{where}/{META} is not an Arboretum example (no format marker)")
    if not isinstance(head.get("schema"), int) or head["schema"] > SCHEMA_VERSION:
        raise ValidationError(f"{where}/{META}: schema {head.get('schema')!r} is newer than this Arboretum reads ({SCHEMA_VERSION})")
    for key in ("id", "created", "arrays_sha256", "example"):
        if key not in head:
            raise ValidationError(f"{where}/{META}: the field {key!r} is missing")
    return head


def decode(meta_bytes: bytes, npz_bytes: bytes, where: str) -> tuple[Example, dict[str, Any]]:
    """Check and rebuild an example from its two files; ``ValidationError`` says what is wrong."""
    head = _head(meta_bytes, where)
    if hashlib.sha256(npz_bytes).hexdigest() != head["arrays_sha256"]:
        raise ValidationError(f"{where}/{ARRAYS} is corrupt (its SHA-256 differs from the one in {META})")
    arrays = npz_to_arrays(npz_bytes, f"{where}/{ARRAYS}")
    try:
        example = unflatten(Example, head["example"], arrays)
    except ValidationError as exc:
        raise ValidationError(f"{where}/{META}: {exc}") from None
    if example.id != head["id"]:
        raise ValidationError(f"{where}/{META}: id {head['id']!r} differs from the record's {example.id!r}")
    return example, head


def read_folder(folder: Path) -> Folder:
    """Read and check the example in ``folder``. ``StoreError`` names the missing or broken file."""
    try:
        meta_bytes = (folder / META).read_bytes()
        npz_bytes = (folder / ARRAYS).read_bytes()
    except FileNotFoundError as exc:
        raise StoreError(f"example folder {folder} is incomplete: {exc.filename} is missing") from None
    except OSError as exc:
        raise StoreError(f"cannot read {exc.filename}: {exc.strerror}") from None
    try:
        example, head = decode(meta_bytes, npz_bytes, str(folder))
    except ValidationError as exc:
        raise StoreError(str(exc)) from None
    return Folder(example, entry_for(example, head, len(meta_bytes) + len(npz_bytes)))


def check_marker(root: Path, create: bool) -> None:
    """Check ``root/library.json`` (or create the library when ``create``); ``InputError`` otherwise,
    ``DiskError`` when the library cannot be created (a full disk: nothing is left behind)."""
    marker = root / "library.json"
    if root.exists() and not root.is_dir():
        raise InputError(f"{root} is a file, not an Arboretum library folder")
    if not marker.exists():
        if root.is_dir() and any(p for p in root.iterdir() if not _MARKER_TEMP.fullmatch(p.name)) and create:
            raise InputError(f"{root} is not an Arboretum library (no library.json) and is not empty")
        if not create:
            what = "is not an Arboretum library (no library.json)" if root.exists() else "does not exist"
            raise InputError(f"library {root} {what}")
        if (outer := enclosing_library(root)) is not None:
            raise InputError(f"library {root}: lies inside the library {outer}, whose folders only it "
                             "writes; create the new library outside it")
        _create_marker(root)
        return
    try:
        head = json.loads(marker.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{marker} is not readable JSON ({exc})") from None
    if not isinstance(head, dict) or head.get("format") != LIBRARY_FORMAT:
        raise InputError(f"{root} is not an Arboretum library ({marker} has no '{LIBRARY_FORMAT}' marker)")
    if not isinstance(head.get("schema"), int) or head["schema"] > SCHEMA_VERSION:
        raise InputError(f"library {root} has schema {head.get('schema')!r}, newer than this Arboretum reads ({SCHEMA_VERSION})")


_MARKER_TEMP = re.compile(r"\.library\.json\.(\d+)\.tmp")
"""The temporary name ``library.json`` is written under (with the writer's pid) before its rename."""


def _create_marker(root: Path) -> None:
    """Write ``root/library.json`` through a temporary file, making ``root`` if missing. When that fails
    (a full disk, Ctrl-C) the temporary file goes, and so does ``root`` if this call made it, so a retry
    finds the folder as it was; a temporary file that a dead process left is removed."""
    made = not root.exists()
    tmp = root / f".library.json.{os.getpid()}.tmp"
    try:
        root.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps({"format": LIBRARY_FORMAT, "schema": SCHEMA_VERSION, "created": now_utc()}) + "\n")
        os.replace(tmp, root / "library.json")
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if made:
            with contextlib.suppress(OSError):
                root.rmdir()
        if isinstance(exc, OSError):
            raise disk_error(root, exc, "it was not created") from None
        raise
    for p in root.iterdir():
        if (m := _MARKER_TEMP.fullmatch(p.name)) and not _alive(int(m.group(1))):
            p.unlink(missing_ok=True)  # a temporary file of a creation that died (another's is in use)


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` runs (on this machine; one we may not signal runs too)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except PermissionError:
        return True
    except (ProcessLookupError, OverflowError):
        return False
    return True


class DiskError(StoreError, OSError):
    """A library write failed for a reason of the disk (full, read-only, an I/O error). A ``StoreError``
    (its ``str`` is one line for the user) that is also the ``OSError`` (with its ``errno``) it came from."""

    cause = ""
    """The OSError's own words: "No space left on device: FILE"."""

    def __str__(self) -> str:
        return str(self.strerror)


def disk_failure(exc: BaseException, catalog: Path) -> OSError | None:
    """``exc`` as an ``OSError`` when the disk caused it (SQLite's "database or disk is full" on the
    ``catalog`` file becomes ENOSPC naming it), else None."""
    if isinstance(exc, OSError):
        return exc
    if isinstance(exc, sqlite3.OperationalError) and getattr(exc, "sqlite_errorname", "") == "SQLITE_FULL":
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(catalog))
    return None


def disk_error(root: Path, exc: OSError, outcome: str) -> DiskError:
    """``DiskError``: "library ROOT: no space left on device (ENOSPC, FILE); OUTCOME" for ``exc``."""
    if isinstance(exc, DiskError):
        return exc
    why = str(exc.strerror or exc)
    detail = ", ".join(str(d) for d in (errno.errorcode.get(exc.errno or 0, ""), exc.filename) if d)
    reason = f"{why[:1].lower()}{why[1:]}{f' ({detail})' if detail else ''}"
    err = DiskError(exc.errno or errno.EIO, f"library {root}: {reason}; {outcome}")
    err.cause = f"{why}: {exc.filename}" if exc.filename else why
    return err


@contextlib.contextmanager
def disk_errors(root: Path, outcome: str | Callable[[], str]) -> Iterator[None]:
    """Raise what fails inside because of the disk (``disk_failure``) as ``disk_error(root, ...,
    outcome)`` (``outcome`` may be a function, asked once it failed); anything else as it is."""
    try:
        yield
    except BaseException as exc:
        if (cause := disk_failure(exc, root / "catalog.sqlite")) is None:
            raise
        raise disk_error(root, cause, outcome if isinstance(outcome, str) else outcome()) from None


def enclosing_library(path: Path) -> Path | None:
    """The nearest folder above ``path`` (links resolved) holding an Arboretum ``library.json`` (one
    with our format marker: other tools, e.g. PlatformIO, write files of that name too), or None."""
    try:
        parents = Path(path).resolve().parents
    except (OSError, RuntimeError):  # a link loop
        return None
    return next((p for p in parents if _is_marker(p / "library.json")), None)


def _is_marker(path: Path) -> bool:
    """Whether ``path`` is an Arboretum ``library.json`` (read at most 64 KiB; ours is one short line)."""
    try:
        with open(path, "rb") as f:
            head = json.loads(f.read(65536))
    except (OSError, ValueError, RecursionError):  # missing, a folder, unreadable, not JSON, nested deep
        return False
    return isinstance(head, dict) and head.get("format") == LIBRARY_FORMAT


def safe_prefix(text: str) -> str:
    """``text`` made an id prefix: every character but letters, digits, '-' and '_' becomes '-', leading
    and trailing '-'/'_' are stripped, at most 110 characters; 'ex' when nothing is left
    (``apple tree (2)`` -> ``apple-tree--2``). ``free_ids`` and the build's ``scan_stem`` both use it."""
    return re.sub(r"[^\w-]", "-", text).strip("-_")[:110] or "ex"


QUARANTINE = "quarantine"
"""Folder beside ``examples`` where recovery moves damaged example folders, each as ``ID-HEX``."""


def quarantine_name(id_: str, token: str) -> str:
    """The name a damaged example ``id_``'s folder gets in ``QUARANTINE`` (``token``: a few hex digits that
    keep two quarantines of one id apart)."""
    return f"{id_}-{token}"


def quarantined(root: Path) -> list[tuple[str, Path]]:
    """(example id, folder) of every folder in the library at ``root``'s ``QUARANTINE`` (none if absent)."""
    qdir = Path(root) / QUARANTINE
    return [(q.name.rsplit("-", 1)[0], q) for q in qdir.iterdir()] if qdir.is_dir() else []


def free_ids(taken_ids: list[str], examples: Path, prefix: str, count: int) -> list[str]:
    """``count`` ids ``PREFIX-NNNN`` after the highest number with that prefix in ``taken_ids`` or among
    the folders in ``quarantine/`` beside ``examples`` (named ``ID-HEX``, see ``recovery``: a damaged
    example's id is not given to another example while its folder is there), skipping any with a folder in ``examples``
    (``prefix`` made safe first, ``safe_prefix``)."""
    prefix = safe_prefix(prefix)
    pattern = re.compile(re.escape(prefix) + r"-(\d+)$")
    held = [id_ for id_, _ in quarantined(examples.parent)]
    taken = [int(m.group(1)) for i in [*taken_ids, *held] if (m := pattern.match(i))]
    out, n = [], max(taken, default=0) + 1
    while len(out) < count:
        if not (examples / f"{prefix}-{n:04d}").exists():
            out.append(f"{prefix}-{n:04d}")
        n += 1
    return out


def read_provenance(folder: Path) -> Provenance:
    """The provenance of the example in ``folder``, from its meta.json alone (its arrays are neither read
    nor checked). ``FileNotFoundError`` when there is none; ``StoreError`` names a broken one."""
    meta = (folder / META).read_bytes()
    try:
        head = _head(meta, str(folder))
        example = head["example"]
        return unflatten(Provenance, example.get("provenance") if isinstance(example, dict) else None, {})
    except ValidationError as exc:
        raise StoreError(f"example {folder.name} is damaged: {exc}") from None


def read_revision(folder: Path) -> str:
    """Hex SHA-256 of ``folder/meta.json`` (which holds the arrays' SHA-256, so it names the whole example
    version). ``FileNotFoundError`` when there is none."""
    return hashlib.sha256((folder / META).read_bytes()).hexdigest()


def holds(folder: Path, meta: bytes) -> bool:
    """Whether ``folder`` holds an example whose meta.json is ``meta`` (a write put it in place)."""
    try:
        return (folder / META).read_bytes() == meta
    except OSError:
        return False


_RENAME_EXCHANGE = 2
_libc = None


def exchange(a: Path, b: Path) -> bool:
    """Atomically swap two existing directories (Linux ``renameat2``). False when unsupported."""
    global _libc
    if _libc is None:
        name = ctypes.util.find_library("c")
        _libc = ctypes.CDLL(name, use_errno=True) if name else False
    fn = getattr(_libc, "renameat2", None) if _libc else None
    if fn is None:
        return False
    at_fdcwd = -100
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: the filesystem cannot exchange
        return False
    raise OSError(err, os.strerror(err), str(a))
