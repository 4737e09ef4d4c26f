"""Wire framing: round trips, and every kind of malformed input gives one ProtocolError."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from arboretum_library.errors import ProtocolError
from arboretum_library.wire import PROTOCOL_VERSION, Limits, Message, decode, encode


def header(**kw):
    h = {"v": PROTOCOL_VERSION, "id": 1, "type": "ping", "body": {}, "arrays": []}
    h.update(kw)
    return msgpack.packb(h)


def test_round_trip_keeps_values_dtypes_and_shapes():
    arrays = {
        "points": np.arange(12, dtype=np.float32).reshape(4, 3),
        "faces": np.array([[0, 1, 2]], dtype=np.int32),
        "labels": np.array([0, 1, 1], dtype=np.uint8),
        "empty": np.zeros((0, 3), np.float64),
    }
    msg = decode(encode(Message("decompose", 42, {"species": "pine", "n": 3}, arrays)))
    assert (msg.type, msg.id, dict(msg.body)) == ("decompose", 42, {"species": "pine", "n": 3})
    for k, a in arrays.items():
        assert msg.arrays[k].dtype == a.dtype and msg.arrays[k].shape == a.shape
        assert np.array_equal(msg.arrays[k], a)


def test_big_endian_and_non_contiguous_inputs_are_normalised():
    a = np.arange(6, dtype=">f8").reshape(2, 3)[:, ::2]
    out = decode(encode(Message("x", arrays={"a": a}))).arrays["a"]
    assert out.dtype.str == "<f8" and np.array_equal(out, a)


def test_object_arrays_cannot_be_sent():
    with pytest.raises(ProtocolError, match="cannot go on the wire"):
        encode(Message("x", arrays={"a": np.array([{}], dtype=object)}))


@pytest.mark.parametrize(
    "frames, match",
    [
        ([], "empty"),
        ([b"\xc1garbage"], "not valid msgpack"),
        ([msgpack.packb([1, 2])], "must be a map"),
        ([header(v=99)], "version 99 is not supported; this side speaks 1"),
        ([header(type="")], "'type'"),
        ([header(id="x")], "'id'"),
        ([header(body=[1])], "'body'"),
        ([header(arrays=[["a", "<f4", [2]]])], "1 arrays but 0"),
        ([header(arrays=[["a", "|O", [1]]]), b"12345678"], "not allowed"),
        ([header(arrays=[["a", "<f4", [-1]]]), b""], "shape"),
        ([header(arrays=[["a", "<f4", [1, 1, 1, 1, 1]]]), b"1234"], "shape"),
        ([header(arrays=[["a", "<f4", [3]]]), b"12345678"], "needs 12 bytes, frame has 8"),
        ([header(arrays=[["a", "<f8", [1 << 39]]]), b""], "over the limit"),
        ([header(arrays=[["a", "<f4", [1]], ["a", "<f4", [1]]]), b"1234", b"1234"], "twice"),
        ([header(arrays=["nope"]), b""], "spec"),
    ],
)
def test_malformed_messages(frames, match):
    with pytest.raises(ProtocolError, match=match):
        decode(frames)


def test_limits_apply():
    frames = encode(Message("x", arrays={"a": np.zeros(100, np.float64)}))
    with pytest.raises(ProtocolError, match="over the limit"):
        decode(frames, Limits(max_array_bytes=100))


@settings(max_examples=300)
@given(st.lists(st.binary(max_size=64), min_size=0, max_size=4))
def test_random_frames_never_raise_anything_but_protocol_error(frames):
    try:
        decode(frames)
    except ProtocolError:
        pass
