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
from collections.abc import Mapping
from enum import IntEnum
from typing import Any, TypeVar, get_args, get_origin, get_type_hints

import numpy as np

from .errors import ValidationError

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
            if key not in arrays:
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
            except TypeError as exc:
                raise ValidationError(f"{where}: {exc}") from None
        origin = get_origin(tp)
        if origin is tuple:
            if not isinstance(v, list):
                raise ValidationError(f"{where}: expected a list")
            elem = get_args(tp)[0]
            return tuple(dec(elem, x, f"{where}[{i}]") for i, x in enumerate(v))
        if tp in (int, float, str, bool) or (isinstance(tp, type) and issubclass(tp, IntEnum)):
            try:
                return tp(v)
            except (TypeError, ValueError):
                raise ValidationError(f"{where}: {v!r} is not a valid {tp.__name__}") from None
        return v

    return dec(cls, meta, cls.__name__)


def arrays_to_npz(arrays: Mapping[str, np.ndarray]) -> bytes:
    """Serialise named arrays to the bytes of an uncompressed .npz (no pickled objects)."""
    buf = io.BytesIO()
    np.savez(buf, **{k: np.ascontiguousarray(a) for k, a in arrays.items()})
    return buf.getvalue()


def npz_to_arrays(data: bytes | io.BufferedIOBase, where: str = "npz") -> dict[str, np.ndarray]:
    """Read every array of an .npz, refusing pickled object arrays."""
    src = io.BytesIO(data) if isinstance(data, bytes) else data
    try:
        with np.load(src, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError) as exc:
        raise ValidationError(f"{where}: not a readable .npz ({exc})") from None
