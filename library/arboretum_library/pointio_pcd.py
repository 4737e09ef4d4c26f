"""PCD v0.7 point clouds (ascii, binary and binary_compressed with LZF), behind ``pointio.read_points``."""

from __future__ import annotations

import io
import struct
from pathlib import Path
from typing import Any

import numpy as np

from .pointio_formats import MAX_HEADER_LINES, Raw, fail, from_named
from .pointio_text import parse_table

_PCD_TYPES = {"F": "f", "U": "u", "I": "i"}


def _pcd_header(path: Path, data: bytes) -> tuple[dict[str, list[str]], int, int]:
    """Header fields, the byte offset of the data and the number of header lines."""
    header: dict[str, list[str]] = {}
    pos, nlines = 0, 0
    while pos < len(data) and nlines < MAX_HEADER_LINES:
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        line = data[pos:end].decode("ascii", "replace").strip()
        pos, nlines = end + 1, nlines + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            return header, pos, nlines
    raise fail(path, "is not a PCD file: no DATA line in its header")


def _pcd_dtype(path: Path, header: dict[str, list[str]]) -> np.dtype:
    fields = header.get("FIELDS", [])
    sizes = header.get("SIZE", [])
    types = header.get("TYPE", [])
    counts = header.get("COUNT", ["1"] * len(fields))
    if not fields or not len(fields) == len(sizes) == len(types) == len(counts):
        raise fail(
            path, "PCD header: FIELDS, SIZE, TYPE and COUNT must list the same number of fields"
        )
    spec = []
    for i, (name, size, kind, count) in enumerate(zip(fields, sizes, types, counts)):
        if kind.upper() not in _PCD_TYPES:
            raise fail(path, f"PCD header: unknown TYPE {kind!r} for field {name!r}")
        base = f"<{_PCD_TYPES[kind.upper()]}{size}"
        spec.append(
            (f"{name}_{i}" if name == "_" else name, base, (int(count),) if int(count) > 1 else ())
        )
    return np.dtype(spec)


def read_pcd(path: Path) -> Raw:
    data = path.read_bytes()
    if not data:
        raise fail(path, "is empty: no points")
    header, offset, nlines = _pcd_header(path, data)
    try:
        dtype = _pcd_dtype(path, header)
        npoints = int(header.get("POINTS", ["0"])[0])
    except (ValueError, TypeError):
        raise fail(path, "PCD header has a malformed SIZE, TYPE, COUNT or POINTS value") from None
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if mode == "ascii":
        table = read_text_table(path, data[offset:], nlines)
        want = sum(int(np.prod(dtype[n].shape)) for n in dtype.names or ())
        if table.shape[1] != want:
            raise fail(
                path,
                f"PCD rows hold {table.shape[1]} values, but its FIELDS and COUNT describe {want}",
            )
        columns, col = {}, 0
        for name in dtype.names or ():
            count = int(np.prod(dtype[name].shape))  # 1 for a scalar field
            columns[name] = table[:, col].astype(dtype[name].base) if count == 1 else None
            col += count
        if len(table) != npoints:
            raise fail(
                path, f"its PCD header promises {npoints} points, the data holds {len(table)}"
            )
    elif mode == "binary":
        if len(data) - offset < npoints * dtype.itemsize:
            raise fail(
                path,
                f"is truncated: {npoints} points need {npoints * dtype.itemsize} bytes of data, found {len(data) - offset}",
            )
        table = np.frombuffer(data, dtype=dtype, count=npoints, offset=offset)
        columns = {n: table[n] for n in dtype.names or ()}
    elif mode == "binary_compressed":
        columns = _pcd_compressed(path, data[offset:], dtype, npoints)
    else:
        raise fail(
            path, f"unknown PCD DATA mode {mode!r} (expected ascii, binary or binary_compressed)"
        )
    return _pcd_raw(path, columns)


def _pcd_compressed(
    path: Path, data: bytes, dtype: np.dtype, npoints: int
) -> dict[str, np.ndarray]:
    """Columns of LZF-compressed PCD data: two uint32 sizes, then each field's values one after another."""
    if len(data) < 8:
        raise fail(path, "is truncated: the compressed PCD data has no size header")
    packed, unpacked = struct.unpack("<II", data[:8])
    if len(data) - 8 < packed:
        raise fail(
            path, f"is truncated: {packed} bytes of compressed data expected, found {len(data) - 8}"
        )
    if unpacked != npoints * dtype.itemsize:
        raise fail(
            path,
            f"compressed PCD data unpacks to {unpacked} bytes, {npoints} points need {npoints * dtype.itemsize}",
        )
    raw = lzf_decompress(data[8 : 8 + packed], unpacked)
    if len(raw) != unpacked:
        raise fail(path, "compressed PCD data is corrupt")
    columns, pos = {}, 0
    for name in dtype.names or ():
        field = dtype[name]
        columns[name] = np.frombuffer(
            raw, dtype=field.base, count=npoints * max(1, int(np.prod(field.shape))), offset=pos
        )
        pos += npoints * field.itemsize
    return columns


def lzf_decompress(src: bytes, size: int) -> bytes:
    """Decompress LZF (liblzf's format, as in PCD 'binary_compressed') to at most ``size`` bytes."""
    out = bytearray()
    i, n = 0, len(src)
    while i < n and len(out) <= size:
        ctrl = src[i]
        i += 1
        if ctrl < 32:  # a literal run of ctrl + 1 bytes
            out += src[i : i + ctrl + 1]
            i += ctrl + 1
            continue
        length = ctrl >> 5
        if length == 7:
            length += src[i] if i < n else 0
            i += 1
        start = len(out) - ((ctrl & 0x1F) << 8) - (src[i] if i < n else 0) - 1
        i += 1
        length += 2
        if start < 0:
            break
        if start + length <= len(out):
            out += out[start : start + length]
        else:  # the copy overlaps what it produces
            for k in range(length):
                out.append(out[start + k])
    return bytes(out)


def read_text_table(path: Path, data: bytes, first_line: int) -> np.ndarray:
    """The ascii data rows ``data`` (after ``first_line`` header lines) as an (R, C>=3) table."""
    return parse_table(path, io.BytesIO(data), first_line + 1)


def _pcd_raw(path: Path, columns: dict[str, Any]) -> Raw:
    named = {k: v for k, v in columns.items() if v is not None and k.lower() not in ("rgb", "rgba")}
    raw = from_named(path, named)
    packed = next((columns[k] for k in columns if k.lower() in ("rgb", "rgba")), None)
    if packed is not None:
        bits = np.asarray(packed)
        # PCL packs 8-bit r, g, b into the bits of one float32 (TYPE F) or uint32 (TYPE U)
        bits = (
            bits.astype(np.float32).view(np.uint32)
            if bits.dtype.kind == "f"
            else bits.astype(np.uint32)
        )
        rgb = np.stack([(bits >> s) & 0xFF for s in (16, 8, 0)], axis=1)
        raw["colors"] = (rgb / 255.0).astype(np.float32)
    return raw
