"""Wire framing: a msgpack header frame, then one raw frame per array. Never pickle.

A message on the wire is a list of ZeroMQ frames::

    frame 0   msgpack map {"v": PROTOCOL_VERSION, "id": request id, "type": message type,
                           "body": JSON-like map, "arrays": [[name, dtype, shape], ...],
                           optional "client": a client's random token, the same in all its retries}
    frame 1.. the raw bytes of each array, in the order of "arrays", C order

Unknown header keys are ignored, so an optional key such as "client" needs no new protocol version.

dtypes carry their byte order ("<f4") and must be in ``DTYPES``; shapes are checked against the frame
size; array and message sizes are limited (``Limits``). ``decode`` turns anything malformed into one
``ProtocolError`` with a message a client can show, and never executes anything from the wire.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np

from .errors import ProtocolError

PROTOCOL_VERSION = 1

DTYPES = frozenset({"<f4", "<f8", "<i4", "<i8", "<u4", "|u1", "|i1", "|b1", "<u2", "<i2"})
"""Array dtypes accepted on the wire (little-endian numbers, bytes, booleans)."""


@dataclass(frozen=True)
class Limits:
    """What a peer may send at most."""

    max_header_bytes: int = 1 << 20
    max_arrays: int = 4096
    max_array_bytes: int = 1 << 30
    max_message_bytes: int = 2 << 30
    max_ndim: int = 4


DEFAULT_LIMITS = Limits()


@dataclass(frozen=True)
class Message:
    """A decoded message: its type, request id, JSON-like body and named arrays."""

    type: str
    id: int = 0
    body: Mapping[str, Any] = field(default_factory=dict)
    arrays: Mapping[str, np.ndarray] = field(default_factory=dict)
    client: str = ""
    """The sender's client token ("" if none): a server keys replies and jobs by it, so a client can
    retry on a new socket; clients without one share one origin."""


MAX_CLIENT_TOKEN = 64
"""Characters a "client" token may have at most."""


def encode(msg: Message) -> list[bytes | memoryview]:
    """Frames for ``msg``: a header and zero-copy views of each (C-contiguous) array."""
    specs, frames = [], []
    for name, arr in msg.arrays.items():
        a = np.ascontiguousarray(arr)
        if a.dtype.str not in DTYPES:
            a = a.astype(a.dtype.newbyteorder("<"))
        if a.dtype.str not in DTYPES:
            raise ProtocolError(f"array {name!r}: dtype {a.dtype.str} cannot go on the wire")
        specs.append([name, a.dtype.str, list(a.shape)])
        frames.append(memoryview(a).cast("B") if a.size else b"")
    header = {"v": PROTOCOL_VERSION, "id": msg.id, "type": msg.type, "body": dict(msg.body), "arrays": specs}
    if msg.client:
        header["client"] = msg.client
    return [msgpack.packb(header, use_bin_type=True), *frames]


def decode(frames: Sequence[bytes | memoryview], limits: Limits = DEFAULT_LIMITS) -> Message:
    """Parse and check ``frames``; raise ``ProtocolError`` describing the first problem found."""
    if not frames:
        raise ProtocolError("empty message")
    header = _header(frames[0], limits)
    specs = header["arrays"]
    if len(specs) != len(frames) - 1:
        raise ProtocolError(f"header lists {len(specs)} arrays but {len(frames) - 1} array frames came")
    total = len(frames[0])
    arrays = {}
    for spec, frame in zip(specs, frames[1:]):
        name, arr = _array(spec, frame, limits)
        total += arr.nbytes
        if total > limits.max_message_bytes:
            raise ProtocolError(f"message is larger than {limits.max_message_bytes} bytes")
        if name in arrays:
            raise ProtocolError(f"array {name!r} appears twice")
        arrays[name] = arr
    return Message(header["type"], header["id"], header["body"], arrays, header.get("client", ""))


def _header(frame: bytes | memoryview, limits: Limits) -> dict:
    if len(frame) > limits.max_header_bytes:
        raise ProtocolError(f"header frame is larger than {limits.max_header_bytes} bytes")
    if not len(frame):
        raise ProtocolError("header frame is empty (a REQ socket's empty delimiter frame where a header belongs?)")
    try:
        h = msgpack.unpackb(bytes(frame), raw=False, strict_map_key=True, max_bin_len=0, max_ext_len=0)
    except ValueError as exc:
        if "max_bin_len" in str(exc) or "max_ext_len" in str(exc):
            raise ProtocolError("header holds binary data; bytes travel as array frames (dtype |u1), "
                                "the header takes only maps, lists, strings, numbers, booleans and nil") from None
        raise ProtocolError(f"header frame is not valid msgpack ({exc or type(exc).__name__})") from None
    except Exception as exc:  # msgpack raises many types on garbage
        raise ProtocolError(f"header frame is not valid msgpack ({type(exc).__name__})") from None
    if not isinstance(h, dict):
        raise ProtocolError("header frame must be a map")
    version = h.get("v")
    if not isinstance(version, int) or isinstance(version, bool):
        raise ProtocolError(f"header 'v' (the protocol version) must be an integer, got {type(version).__name__}")
    if version != PROTOCOL_VERSION:
        raise ProtocolError(f"protocol version {version!r} is not supported; this side speaks {PROTOCOL_VERSION}")
    if not isinstance(h.get("type"), str) or not h["type"]:
        raise ProtocolError("header 'type' must be a non-empty string")
    if not isinstance(h.get("id", 0), int) or isinstance(h.get("id", 0), bool):
        raise ProtocolError("header 'id' must be an integer")
    if not isinstance(h.get("body", {}), dict):
        raise ProtocolError("header 'body' must be a map")
    specs = h.get("arrays", [])
    if not isinstance(specs, list) or len(specs) > limits.max_arrays:
        raise ProtocolError(f"header 'arrays' must be a list of at most {limits.max_arrays} specs")
    client = h.get("client", "")
    if not isinstance(client, str) or len(client) > MAX_CLIENT_TOKEN:
        raise ProtocolError(f"header 'client' must be a string of at most {MAX_CLIENT_TOKEN} characters")
    h.setdefault("id", 0)
    h.setdefault("body", {})
    h["arrays"] = specs
    return h


def _array(spec: Any, frame: bytes | memoryview, limits: Limits) -> tuple[str, np.ndarray]:
    if not (isinstance(spec, list) and len(spec) == 3 and isinstance(spec[0], str) and isinstance(spec[1], str)):
        raise ProtocolError("each array spec must be [name, dtype, shape]")
    name, dtype, shape = spec
    if dtype not in DTYPES:
        raise ProtocolError(f"array {name!r}: dtype {dtype!r} is not allowed (allowed: {', '.join(sorted(DTYPES))})")
    if (
        not isinstance(shape, list)
        or len(shape) > limits.max_ndim
        or not all(isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 1 << 40 for s in shape)
    ):
        raise ProtocolError(f"array {name!r}: shape must be a list of at most {limits.max_ndim} sizes >= 0")
    itemsize = np.dtype(dtype).itemsize
    if math.prod(s for s in shape if s) * itemsize > limits.max_array_bytes:  # also for empty arrays
        raise ProtocolError(f"array {name!r}: shape {shape} is over the limit of {limits.max_array_bytes} bytes")
    nbytes = int(np.prod(shape, dtype=np.float64)) * itemsize
    if nbytes > limits.max_array_bytes:
        raise ProtocolError(f"array {name!r}: {nbytes} bytes is over the limit of {limits.max_array_bytes}")
    if nbytes != len(frame):
        raise ProtocolError(f"array {name!r}: shape {shape} of {dtype} needs {nbytes} bytes, frame has {len(frame)}")
    arr = np.frombuffer(frame, dtype=dtype).reshape(shape) if nbytes else np.zeros(shape, dtype)
    return name, arr
