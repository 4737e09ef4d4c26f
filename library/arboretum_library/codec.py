"""Records <-> (JSON-able metadata, named arrays): one codec for the example store and the wire.

``flatten`` walks a record (frozen dataclasses, tuples, arrays, numbers, strings, JSON mappings) and
returns a metadata tree in which every array is replaced by ``{"$array": KEY}``, plus the arrays by
KEY. ``unflatten`` rebuilds the record from its type's annotations, so the records themselves validate
what comes back. No pickle anywhere: arrays go to .npz files (``allow_pickle=False``) or raw frames.
"""

from __future__ import annotations

import dataclasses
import functools
import io
import json
import os
import threading
import tokenize
import zipfile
import zlib
from collections.abc import Mapping
from enum import IntEnum
from pathlib import Path
from typing import Any, TypeVar, get_args, get_origin, get_type_hints

import numpy as np

from .errors import InputError, ValidationError
from .npzwrite import npz_bytes

try:
    from lzma import LZMAError
except ImportError:  # a Python built without lzma: zipfile cannot read (or raise) it either
    LZMAError = zlib.error

T = TypeVar("T")
ARRAY = "$array"


def flatten(record: Any) -> tuple[Any, dict[str, np.ndarray]]:
    """Split ``record`` into JSON-able metadata and a dict of arrays keyed by their path."""
    arrays: dict[str, np.ndarray] = {}

    def enc(v: Any, path: str) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: enc(getattr(v, f.name), f"{path}{f.name}/") for f in dataclasses.fields(v)}
        if isinstance(v, np.ndarray):
            key = path.rstrip("/")
            arrays[key] = v
            return {ARRAY: key}
        if isinstance(v, IntEnum):
            return int(v)
        if isinstance(v, (np.integer, np.floating, np.bool_)):
            return v.item()
        if isinstance(v, (tuple, list)):
            return [enc(x, f"{path}{i}/") for i, x in enumerate(v)]
        if isinstance(v, Mapping):
            return {str(k): enc(x, f"{path}{k}/") for k, x in v.items()}
        return v

    return enc(record, ""), arrays


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return get_type_hints(cls)


def unflatten(cls: type[T], meta: Any, arrays: Mapping[str, np.ndarray]) -> T:
    """Rebuild a ``cls`` record from ``flatten`` output. Raises ``ValidationError`` on any mismatch."""

    def dec(tp: Any, v: Any, where: str) -> Any:
        if isinstance(v, dict) and ARRAY in v:
            key = v[ARRAY]
            if not isinstance(key, str) or key not in arrays:
                raise ValidationError(f"{where}: array {key!r} is missing")
            return arrays[key]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            if not isinstance(v, dict):
                raise ValidationError(f"{where}: expected an object for {tp.__name__}")
            hints = _hints(tp)
            known = {f.name for f in dataclasses.fields(tp)}
            kwargs = {k: dec(hints[k], x, f"{where}.{k}") for k, x in v.items() if k in known}
            try:
                return tp(**kwargs)
            except (TypeError, OverflowError) as exc:
                raise ValidationError(f"{where}: {exc}") from None
        origin = get_origin(tp)
        if origin is tuple:
            if not isinstance(v, list):
                raise ValidationError(f"{where}: expected a list")
            elem = get_args(tp)[0]
            return tuple(dec(elem, x, f"{where}[{i}]") for i, x in enumerate(v))
        if tp in (int, float, str, bool) or (isinstance(tp, type) and issubclass(tp, IntEnum)):
            try:
                return tp(_integer(v, where)) if tp is int or issubclass(tp, IntEnum) else tp(v)
            except (TypeError, ValueError, OverflowError):
                raise ValidationError(f"{where}: {v!r} is not a valid {tp.__name__}") from None
        return v

    return dec(cls, meta, cls.__name__)


MAX_INT = (1 << 63) - 1
"""Largest integer a record field takes (int64): anything beyond cannot be an index or a count."""


def _integer(v: Any, where: str) -> int:
    """``v`` as an int: an integer, or a float with an integral value, within int64; else ``ValidationError``."""
    n = int(v) if isinstance(v, float) and v.is_integer() else v
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or abs(int(n)) > MAX_INT:
        shown = f"{v:.6g}" if isinstance(v, float | int) and not isinstance(v, bool) else repr(v)[:60]
        raise ValidationError(f"{where}: {shown} is not a valid integer (a whole number within int64)")
    return int(n)


def arrays_to_npz(arrays: Mapping[str, np.ndarray], *, compress: bool = False) -> bytes:
    """Serialise named arrays to the bytes of an .npz, deflated when ``compress`` (no pickled objects).

    Uncompressed, the bytes are exactly ``np.savez``'s (their SHA-256 identifies a stored example), written
    by ``npzwrite`` without zipfile's per-member cost; ``np.savez`` itself whenever that writer declines.
    """
    contiguous = {k: np.ascontiguousarray(a) for k, a in arrays.items()}
    if not compress and (data := npz_bytes(contiguous)) is not None:
        return data
    buf = io.BytesIO()
    save = np.savez_compressed if compress else np.savez
    save(buf, **contiguous)
    return buf.getvalue()


_DAMAGED = (ValueError, OSError, EOFError, TypeError, IndexError, OverflowError, MemoryError,
            NotImplementedError, SyntaxError, zlib.error, LZMAError, zipfile.BadZipFile, tokenize.TokenError)
"""What reading a cut, corrupted or hostile .npz raises on numpy 2.4 / Python 3.11 (found by fuzzing,
see tests/test_codec_fuzz.py):

- the zip: ``BadZipFile`` (directory, header, CRC), ``NotImplementedError`` (zip version, flag bits,
  compression method), ``zlib.error``, ``LZMAError``, ``OSError`` (bz2) or ``EOFError`` from a bad or
  short stream, ``ValueError`` (a negative seek), ``EOFError`` (no bytes at all);
- a .npy header: ``ValueError`` (numpy's checks, text that does not decode), ``TypeError`` (an
  unhashable dict key), ``IndexError`` (a ``descr`` that is an empty tuple or
  holds one, e.g. ``()``, ``[('a', ())]`` or ``(('<f8', (2,)),)``: numpy's ``descr_to_dtype`` indexes
  it), ``SyntaxError``/``TokenError`` (numpy's header filter), ``OverflowError`` (a
  dimension beyond int64) and ``MemoryError`` when it declares a shape of terabytes: numpy allocates the
  array before reading its bytes.

Encrypted members (zipfile's ``RuntimeError``) are refused before reading, so a ``RuntimeError`` (or a
``RecursionError``) still shows as the bug it is."""

_ENCRYPTED = 0x1
"""Bit 0 of a zip member's general purpose flags: encrypted (zipfile would raise ``RuntimeError``)."""


def npz_to_arrays(data: bytes | io.BufferedIOBase, where: str = "npz") -> dict[str, np.ndarray]:
    """Read every array of an .npz, refusing pickled object arrays; ``ValidationError`` if it is damaged."""
    src = io.BytesIO(data) if isinstance(data, bytes) else data
    head = src.read(6)
    src.seek(-len(head), io.SEEK_CUR)
    if head and not head.startswith(b"PK"):  # not a zip: numpy's own message would advise allow_pickle
        what = "one .npy array, not a zip of arrays" if head == b"\x93NUMPY" else "not a zip archive"
        raise ValidationError(f"{where}: not a readable .npz ({what})")
    try:
        with np.load(src, allow_pickle=False) as z:  # a zip by its first bytes (above): an NpzFile
            locked = [m.filename for m in z.zip.infolist() if m.flag_bits & _ENCRYPTED]
            if locked:
                raise ValidationError(f"{where}: not a readable .npz ({locked[0]!r} is encrypted)")
            arrays = {k: z[k] for k in z.files}
    except _DAMAGED as exc:
        detail = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
        raise ValidationError(f"{where}: not a readable .npz, damaged or cut short ({detail})") from None
    for k, v in arrays.items():
        if not isinstance(v, np.ndarray):  # numpy hands back the raw bytes of a member that is not .npy
            raise ValidationError(f"{where}: not a readable .npz, damaged or cut short ({k!r} is not an array)")
    return arrays


META_KEY = "__meta__"
"""Key of the JSON metadata inside a record .npz (stored as a uint8 array of UTF-8 bytes)."""
RECORD_SCHEMA = 1


def save_record(path: str | os.PathLike, record: Any, *, compress: bool = False, fsync: bool = False) -> Path:
    """Write ``record`` to one .npz file atomically (temp file + rename); returns the path.

    The file holds every array under its path key and ``__meta__``: JSON ``{"kind": type name,
    "schema": RECORD_SCHEMA, "record": metadata}``. Readable by any numpy, no pickle. With ``fsync`` the
    temp file is fsynced before the rename and the folder after it, so the new file survives power loss.
    """
    path = Path(path)
    meta, arrays = flatten(record)
    head = {"kind": type(record).__name__, "schema": RECORD_SCHEMA, "record": meta}
    arrays = dict(arrays)
    arrays[META_KEY] = np.frombuffer(json.dumps(head).encode(), dtype=np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(arrays_to_npz(arrays, compress=compress))
            if fsync:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    if fsync:
        fsync_dir(path.parent)
    return path


def fsync_dir(folder: str | os.PathLike) -> None:
    """Make renames, creations and deletions in ``folder`` durable (POSIX: fsync the directory)."""
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def record_kind(path: str | os.PathLike) -> str:
    """The record type name stored in a .npz written by ``save_record``."""
    return _read_record_file(Path(path))[0]["kind"]


def load_record(path: str | os.PathLike, cls: type[T]) -> T:
    """Read a ``cls`` record written by ``save_record``; ``InputError`` names the file on any problem."""
    path = Path(path)
    head, arrays = _read_record_file(path)
    if head.get("kind") != cls.__name__:
        raise InputError(f"{path}: holds a {head.get('kind')!r} record, expected {cls.__name__}")
    if "record" not in head:
        raise InputError(f"{path}: its {META_KEY} entry has no 'record'")
    try:
        return unflatten(cls, head["record"], arrays)
    except ValidationError as exc:
        raise InputError(f"{path}: {exc}") from None


def _read_record_file(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        arrays = npz_to_arrays(path.read_bytes(), str(path))
    except ValidationError as exc:
        raise InputError(str(exc)) from None
    raw = arrays.pop(META_KEY, None)
    if raw is None:
        raise InputError(f"{path}: not an Arboretum record file (no {META_KEY} entry)")
    try:
        head = json.loads(raw.tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError(f"{path}: its {META_KEY} entry is not valid JSON") from None
    schema = head.get("schema", 0) if isinstance(head, dict) else None
    if not isinstance(schema, int):
        raise InputError(f"{path}: its {META_KEY} entry has no valid record schema")
    if schema > RECORD_SCHEMA:
        raise InputError(f"{path}: record schema {schema} is newer than this Arboretum reads ({RECORD_SCHEMA})")
    return head, arrays
