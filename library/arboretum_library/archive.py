"""A whole library in one archive file: an uncompressed POSIX tar with a manifest.

Members (no directories, links or anything else)::

    examples/<id>/meta.json      byte for byte the library's files
    examples/<id>/arrays.npz
    manifest.json                {"format": "arboretum-library-archive", "schema": 1,
                                  "examples": [{"id": ..., "arrays_sha256": ...}, ...]}

An export is reproducible: the same examples give the same bytes. Members come in id order, each
example's two files carry the example's own ``created`` time as their mtime (the manifest the latest
of them), and the manifest holds no clock time (older archives have a ``created`` field there, which
import never read and still accepts).

Importing reads every member (``tarfile`` also accepts .tar.gz/.tar.bz2/.tar.xz), refuses any name
that is not one of the above (so nothing can land outside the library: no '..', no absolute paths, no
links), and validates every example before adding any. A corrupt or foreign archive raises one
``InputError`` and changes nothing. Examples are then added one by one, each atomically.
"""

from __future__ import annotations

import calendar
import dataclasses
import io
import json
import os
import re
import tarfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from .catalog import SCHEMA_VERSION
from .errors import InputError, StoreError, ValidationError
from .folders import ARRAYS, META, decode, encode, valid_id
from .model import Example
from .outputs import check_output
from .progress import ProgressFn, no_progress

ARCHIVE_FORMAT = "arboretum-library-archive"
MANIFEST = "manifest.json"
CONFLICTS = ("skip", "replace", "rename")
_MEMBER = re.compile(r"examples/([^/]+)/(meta\.json|arrays\.npz)")


@dataclass
class ImportReport:
    """What ``import_archive`` did with each example of the archive."""

    added: list[str] = field(default_factory=list)
    replaced: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    """Ids already in the library and left as they were (on_conflict='skip')."""
    renamed: dict[str, str] = field(default_factory=dict)
    """Archive id -> the new id it was stored under (on_conflict='rename')."""

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class CheckedArchive:
    """An archive whose every example was validated; ``ids`` in manifest order."""

    path: Path
    ids: tuple[str, ...]


def export_archive(lib, path: Path, progress: ProgressFn = no_progress) -> dict:
    """Write every example of ``lib`` (a ``Library``) to the tar ``path`` (temp file, then rename).

    ``path`` is checked first (``outputs.check_output``: not a folder, its folder exists and can be
    written, not inside the library): an ``InputError`` names it, not the temporary file. So does a write
    failing later (a full disk: an ``OSError`` with no file name); a library file that cannot be read is
    a ``StoreError`` naming its folder. The temporary file is removed either way."""
    path = check_output(path, "ARCHIVE", libraries=[lib.root])
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with tarfile.open(tmp, "w", format=tarfile.PAX_FORMAT) as tf:
            listed = _write_examples(tf, lib, progress)
            manifest = {"format": ARCHIVE_FORMAT, "schema": SCHEMA_VERSION,
                        "examples": [{"id": e["id"], "arrays_sha256": e["arrays_sha256"]} for e in listed]}
            _add_member(tf, MANIFEST, json.dumps(manifest, indent=1).encode(),
                        max((e["mtime"] for e in listed), default=0))
        os.replace(tmp, path)
    except OSError as exc:  # a failing write() (full disk, file too large) names no file
        if exc.filename is not None and Path(exc.filename) not in (tmp, path):
            raise
        raise InputError(f"ARCHIVE {path}: cannot write it ({exc.strerror or exc})") from None
    finally:
        tmp.unlink(missing_ok=True)
    return {"archive": str(path), "examples": len(listed), "size_bytes": path.stat().st_size}


def _write_examples(tf: tarfile.TarFile, lib, progress: ProgressFn) -> list[dict]:
    """Add every example's two files to ``tf`` in id order; their manifest entries (with ``mtime``)."""
    listed = []
    ids = sorted(lib.ids())
    for i, id_ in enumerate(ids):
        folder = lib.root / "examples" / id_
        try:
            meta, npz = (folder / META).read_bytes(), (folder / ARRAYS).read_bytes()
        except FileNotFoundError:
            continue  # deleted by another process meanwhile
        except OSError as exc:  # a read error is the library's, never the archive's (see export_archive)
            raise StoreError(f"{folder}: cannot read the example ({exc.strerror or exc})") from None
        try:
            head = decode(meta, npz, str(folder))[1]
        except ValidationError as exc:
            raise StoreError(str(exc)) from None
        mtime = _epoch(head["created"])
        _add_member(tf, f"examples/{id_}/{META}", meta, mtime)
        _add_member(tf, f"examples/{id_}/{ARRAYS}", npz, mtime)
        listed.append({"id": id_, "arrays_sha256": head["arrays_sha256"], "mtime": mtime})
        progress(i + 1, len(ids), "exporting")
    return listed


def _epoch(created: object) -> int:
    """Seconds since 1970 of an example's ``created`` time ("2026-11-22T05:06:39Z"); 0 when it is not
    one (a member's mtime is only for people listing the archive)."""
    try:
        return max(0, calendar.timegm(time.strptime(str(created), "%Y-%m-%dT%H:%M:%SZ")))
    except (ValueError, OverflowError):
        return 0


def _add_member(tf: tarfile.TarFile, name: str, data: bytes, mtime: int) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mode = 0o644
    info.mtime = mtime
    tf.addfile(info, io.BytesIO(data))


def _open(path: Path) -> tuple[tarfile.TarFile, dict[str, tarfile.TarInfo]]:
    """Open the archive and index its members by name, refusing any unexpected or unsafe member."""
    if path.is_dir():
        raise InputError(f"archive {path}: is a folder, not an archive file (make one with "
                         "'arboretum library export LIB ARCHIVE')")
    if not path.is_file():
        raise InputError(f"archive {path} does not exist")
    try:
        tf = tarfile.open(path, "r:*")
        members = tf.getmembers()
    except (tarfile.TarError, OSError, EOFError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else "not a tar file, or truncated"
        raise InputError(f"{path} is not a readable archive ({why})") from None
    by_name: dict[str, tarfile.TarInfo] = {}
    for m in members:
        found = _MEMBER.fullmatch(m.name)
        ok = m.isfile() and (m.name == MANIFEST or (found is not None and valid_id(found.group(1))))
        if not ok or m.name in by_name:
            tf.close()
            raise InputError(f"{path} is not an Arboretum library archive: unexpected member {m.name!r}")
        by_name[m.name] = m
    return tf, by_name


def _read(tf: tarfile.TarFile, member: tarfile.TarInfo, path: Path) -> bytes:
    try:
        f = tf.extractfile(member)
        return f.read() if f else b""
    except (tarfile.TarError, OSError, EOFError):
        raise InputError(f"{path}: member {member.name} is unreadable (truncated archive?)") from None


def _manifest(tf: tarfile.TarFile, by_name: dict, path: Path) -> list[dict]:
    if MANIFEST not in by_name:
        raise InputError(f"{path} is not an Arboretum library archive (no {MANIFEST})")
    try:
        head = json.loads(_read(tf, by_name[MANIFEST], path).decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError(f"{path}: {MANIFEST} is not valid JSON") from None
    if not isinstance(head, dict) or head.get("format") != ARCHIVE_FORMAT:
        raise InputError(f"{path} is not an Arboretum library archive (wrong {MANIFEST} format marker)")
    if not isinstance(head.get("schema"), int) or head["schema"] > SCHEMA_VERSION:
        raise InputError(f"{path}: archive schema {head.get('schema')!r} is newer than this Arboretum reads ({SCHEMA_VERSION})")
    listed = head.get("examples")
    if not isinstance(listed, list) or not all(isinstance(e, dict) and isinstance(e.get("id"), str) for e in listed):
        raise InputError(f"{path}: {MANIFEST} has no valid 'examples' list")
    return listed


def _load(tf: tarfile.TarFile, by_name: dict, path: Path, id_: str) -> tuple[Example, bytes, bytes]:
    """Read and validate example ``id_`` of the archive."""
    names = [f"examples/{id_}/{META}", f"examples/{id_}/{ARRAYS}"]
    missing = [n for n in names if n not in by_name]
    if missing:
        raise InputError(f"{path}: {missing[0]} is missing")
    meta, npz = (_read(tf, by_name[n], path) for n in names)
    try:
        example = decode(meta, npz, f"{path}:examples/{id_}")[0]
    except ValidationError as exc:
        raise InputError(str(exc)) from None
    if example.id != id_:
        raise InputError(f"{path}: examples/{id_} holds example {example.id!r}")
    return example, meta, npz


def check_archive(path: Path) -> CheckedArchive:
    """Validate every member and every example of the archive at ``path`` (nothing is written)."""
    tf, by_name = _open(path)
    with tf:
        listed = _manifest(tf, by_name, path)
        ids = [e["id"] for e in listed]
        on_disk = {m.group(1) for n in by_name if (m := _MEMBER.fullmatch(n))}
        if len(set(ids)) != len(ids) or set(ids) != on_disk:
            raise InputError(f"{path}: {MANIFEST} does not list exactly the examples the archive holds")
        for entry in listed:
            example, meta, _ = _load(tf, by_name, path, entry["id"])
            if json.loads(meta).get("arrays_sha256") != entry.get("arrays_sha256"):
                raise InputError(f"{path}: examples/{entry['id']} does not match its {MANIFEST} checksum")
    return CheckedArchive(path, tuple(ids))


def apply_archive(lib, checked: CheckedArchive, on_conflict: str = "skip",
                  progress: ProgressFn = no_progress) -> ImportReport:
    """Add the examples of a checked archive to ``lib``, each atomically."""
    if on_conflict not in CONFLICTS:
        raise InputError(f"on_conflict must be one of {', '.join(CONFLICTS)}, got {on_conflict!r}")
    report = ImportReport()
    tf, by_name = _open(checked.path)
    with tf:
        for i, id_ in enumerate(checked.ids):
            example, meta, npz = _load(tf, by_name, checked.path, id_)
            with lib.locked():  # the check and the write as one step: another importer may add the same ids
                _apply_one(lib, report, on_conflict, id_, example, meta, npz)
            progress(i + 1, len(checked.ids), "importing")
    return report


def _apply_one(lib, report: ImportReport, on_conflict: str, id_: str, example, meta: bytes, npz: bytes) -> None:
    if id_ not in lib:
        lib.put_encoded(example, meta, npz)
        report.added.append(id_)
    elif on_conflict == "skip":
        report.skipped.append(id_)
    elif on_conflict == "replace":
        lib.put_encoded(example, meta, npz, replace=True)
        report.replaced.append(id_)
    else:
        renamed = dataclasses.replace(example, id=lib.new_id(id_))
        lib.put_encoded(renamed, *encode(renamed, json.loads(meta)["created"]))
        report.renamed[id_] = renamed.id


def import_archive(archive: str | os.PathLike, library: str | os.PathLike, *, on_conflict: str = "skip",
                   fsync: bool = True, progress: ProgressFn = no_progress) -> ImportReport:
    """Validate ``archive`` whole, then add it to the library at ``library`` (created if missing)."""
    from .store import Library

    if on_conflict not in CONFLICTS:
        raise InputError(f"on_conflict must be one of {', '.join(CONFLICTS)}, got {on_conflict!r}")
    checked = check_archive(Path(archive))
    with Library.open(library, create=True, fsync=fsync) as lib:
        return apply_archive(lib, checked, on_conflict, progress)
