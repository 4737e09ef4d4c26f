"""Damaged and hostile .npz files: one ``ValidationError`` each, and only what numpy really raises caught.

``codec._DAMAGED`` lists the exceptions reading a damaged .npz raises; these tests make each of them
happen (the zip cut or flipped, a member's compression method or flags changed, a .npy header garbled
or lying about its shape) and check that a bug elsewhere (``RuntimeError``) is not swallowed.
"""

from __future__ import annotations

import io
import struct
import tokenize
import zipfile
import zlib

import numpy as np
import pytest

from arboretum_library import codec
from arboretum_library.codec import arrays_to_npz, npz_to_arrays
from arboretum_library.errors import ValidationError

REFUSED = "x.npz: not a readable .npz"
ARRAYS = {"a": np.linspace(0, 1, 90).reshape(30, 3), "b": np.arange(50)}


def _zip(members: dict[str, bytes], method: int = zipfile.ZIP_STORED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", method) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def _npy(header: bytes, version: int = 1) -> bytes:
    """A .npy member with this header text (CRC-valid once zipped), followed by 64 zero bytes."""
    length = struct.pack("<H", len(header)) if version == 1 else struct.pack("<I", len(header))
    return b"\x93NUMPY" + bytes([version, 0]) + length + header + b"\0" * 64


def _header(shape: str, descr: str = "'<f8'") -> bytes:
    return f"{{'descr': {descr}, 'fortran_order': False, 'shape': {shape}, }}\n".encode()


def _patch(data: bytes, signature: bytes, offset: int, value: bytes) -> bytes:
    """``data`` with ``value`` written at ``offset`` after every zip record starting with ``signature``."""
    b = bytearray(data)
    start = b.find(signature)
    while start >= 0:
        b[start + offset:start + offset + len(value)] = value
        start = b.find(signature, start + 1)
    return bytes(b)


def _method(data: bytes, method: int) -> bytes:
    """Every member's compression method set to ``method`` (central directory and local headers)."""
    data = _patch(data, b"PK\x01\x02", 10, struct.pack("<H", method))
    return _patch(data, b"PK\x03\x04", 8, struct.pack("<H", method))


def _flags(data: bytes, flags: int) -> bytes:
    return _patch(data, b"PK\x01\x02", 8, struct.pack("<H", flags))


def _refused(data: bytes) -> ValidationError:
    with pytest.raises(ValidationError) as err:
        npz_to_arrays(data, "x.npz")
    assert str(err.value).startswith(REFUSED), str(err.value)
    return err.value


def _deflate_block_type_3() -> bytes:
    """A deflated .npz whose first member's stream starts with the reserved block type 3."""
    b = bytearray(arrays_to_npz(ARRAYS, compress=True))
    name_len, extra_len = struct.unpack("<HH", b[26:30])
    b[30 + name_len + extra_len] = 0b111  # BFINAL=1, BTYPE=11
    return bytes(b)


GOOD = arrays_to_npz(ARRAYS)
BAD_LZMA = b"\x09\x14\x05\x00\xff\x00\x00\x10\x00" + b"\0" * 40  # LZMA properties byte 0xff: invalid

# (case, damaged bytes, what np.load raised (None: refused by npz_to_arrays itself), words in the message)
CASES = [
    ("empty", b"", EOFError, "No data left"),
    ("cut in the directory", GOOD[:-30], zipfile.BadZipFile, "not a zip file"),
    ("version 10.5 needed", _patch(GOOD, b"PK\x01\x02", 6, b"\x69\x00"), NotImplementedError, "version"),
    ("strong encryption flag", _flags(GOOD, 1 << 6), NotImplementedError, "strong encryption"),
    ("unknown compression", _method(GOOD, 99), NotImplementedError, "compression"),
    ("bz2 claimed, not bz2", _method(GOOD, zipfile.ZIP_BZIP2), OSError, "Invalid data stream"),
    ("lzma claimed, bad properties", _method(_zip({"a.npy": BAD_LZMA}), zipfile.ZIP_LZMA), codec.LZMAError,
     "Invalid or unsupported options"),
    ("deflate block type 3", _deflate_block_type_3(), zlib.error, "invalid block type"),
    ("shape of exbibytes", _zip({"a.npy": _npy(_header("(1125899906842624,)"))}), MemoryError, "allocate"),
    ("shape beyond int64", _zip({"a.npy": _npy(_header("(" + "9" * 30 + ",)"))}),
     OverflowError, "too large"),
    ("negative shape", _zip({"a.npy": _npy(_header("(-5,)"))}), ValueError, "negative"),
    ("object dtype", _zip({"a.npy": _npy(_header("(3,)", "'|O'"))}), ValueError, "allow_pickle"),
    ("descr an empty tuple", _zip({"a.npy": _npy(_header("(1,)", "()"))}), IndexError, "out of range"),
    ("descr field an empty tuple", _zip({"a.npy": _npy(_header("(1,)", "[('a', ())]"))}), IndexError,
     "out of range"),
    ("descr a tuple of a tuple", _zip({"a.npy": _npy(_header("(1,)", "(('<f8', (2,)),)"))}), IndexError,
     "out of range"),
    ("unhashable header key", _zip({"a.npy": _npy(b"{[1]: 2}\n")}), TypeError, "unhashable"),
    ("header indentation", _zip({"a.npy": _npy(b"a\n    b\n  c\n")}), SyntaxError, "indent"),
    ("header never closes", _zip({"a.npy": _npy(b"(" * 300 + b"\n")}), tokenize.TokenError,
     "EOF in multi-line"),
    ("header not text", _zip({"a.npy": _npy(b"\xff" * 20, version=3)}), ValueError, "utf-8"),
    ("encrypted member", _flags(GOOD, 1), None, "'a.npy' is encrypted"),
    ("member not .npy", _zip({"a.txt": b"hello"}), None, "'a.txt' is not an array"),
    ("npy magic flipped", _zip({"a.npy": b"C" + _npy(_header("(3,)"))[1:]}), None, "'a' is not an array"),
    ("a bare .npy", _npy(_header("(3,)")), None, "one .npy array"),
    ("a text file", b"0.1 0.2 0.3\n1 2 3\n", None, "not a zip archive"),
]


@pytest.mark.parametrize("name, data, raised, words", CASES, ids=[c[0] for c in CASES])
def test_each_damage_is_one_validation_error_naming_the_cause(name, data, raised, words):
    err = _refused(data)
    cause = err.__context__  # what np.load raised (the message hides it: ``from None``)
    if raised is None:
        assert cause is None, repr(cause)
    else:
        assert isinstance(cause, raised), repr(cause)
    assert words in str(err), str(err)


def test_every_exception_caught_is_one_numpy_really_raises():
    seen = set()
    for _, data, _, _ in CASES:
        with pytest.raises(ValidationError) as err:
            npz_to_arrays(data, "x.npz")
        if err.value.__context__ is not None:
            seen.add(type(err.value.__context__))
    unused = [t.__name__ for t in codec._DAMAGED if not any(issubclass(s, t) for s in seen)]
    assert unused == [], f"caught but never raised by a damaged .npz: {unused}"
    assert not any(issubclass(t, RuntimeError) and t is not NotImplementedError for t in codec._DAMAGED)


def test_a_bug_inside_np_load_is_not_called_damage(monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("a bug, not a damaged file")

    monkeypatch.setattr(np, "load", boom)
    with pytest.raises(RuntimeError, match="a bug"):
        npz_to_arrays(GOOD, "x.npz")


@pytest.mark.parametrize("compress", [False, True])
def test_random_cuts_and_flips_read_or_refuse(compress):
    """Cut anywhere, or 1-3 bytes flipped anywhere (zip directory, local headers, deflate stream) or in a
    .npy header behind a valid CRC: every file reads back as arrays or is one ValidationError."""
    rng = np.random.default_rng(3)
    good = arrays_to_npz(ARRAYS, compress=compress)
    member = io.BytesIO()
    np.save(member, ARRAYS["a"])
    cases = [good[:cut] for cut in range(0, len(good), 5)]
    for _ in range(800):
        b = bytearray(good)
        for pos in rng.integers(0, len(b), int(rng.integers(1, 4))):
            b[pos] = int(rng.integers(256))
        cases.append(bytes(b))
    for _ in range(400):
        b = bytearray(member.getvalue())
        for pos in rng.integers(0, 128, int(rng.integers(1, 4))):
            b[pos] = int(rng.integers(256))
        cases.append(_zip({"a.npy": bytes(b)}, zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED))
    outcomes = {"read": 0, "refused": 0}
    for data in cases:
        try:
            arrays = npz_to_arrays(data, "x.npz")
        except ValidationError as exc:
            assert str(exc).startswith(REFUSED), str(exc)
            outcomes["refused"] += 1
        else:
            assert all(isinstance(v, np.ndarray) for v in arrays.values())
            outcomes["read"] += 1
    assert outcomes["read"] > 0 and outcomes["refused"] > len(cases) // 2, outcomes


def test_a_record_file_with_an_empty_tuple_descr_is_one_input_error(tmp_path):
    """``arboretum render`` and every record loader read through ``load_record``: no traceback."""
    from arboretum_library.assembly import Assembly
    from arboretum_library.codec import load_record
    from arboretum_library.errors import InputError

    path = tmp_path / "bad_record.npz"
    path.write_bytes(_zip({"x.npy": _npy(_header("(1,)", "()"))}))
    with pytest.raises(InputError, match="bad_record.npz: not a readable .npz"):
        load_record(path, Assembly)
