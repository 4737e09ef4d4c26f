"""The envelope of a request as the ROUTER socket receives it: routing frames, then the message.

A DEALER peer's message is (identity, header, arrays...); a REQ peer's is (identity, b"", header,
arrays...), its empty delimiter kept as routing so the reply goes back through it. For a malformed
message, the header is peeked at within small bounds to read back its request id (so the ``Error``
reply can be matched) and its protocol version (so a client of another version is told so).
"""

from __future__ import annotations

from typing import Any

import msgpack

from arboretum_library.errors import ProtocolError
from arboretum_library.wire import PROTOCOL_VERSION

Route = tuple[bytes, ...]
"""Routing frames of a peer: (identity,) for DEALER, (identity, b"") for REQ."""


def split_route(frames: list) -> tuple[Route, list] | None:
    """(route, message frames) of a received multipart message; None when it has no message frame."""
    if len(frames) < 2:
        return None
    route, body = (bytes(frames[0]),), frames[1:]
    if len(body) > 1 and not len(body[0]) and is_header(body[1]):
        route, body = (route[0], b""), body[1:]  # a REQ peer: an empty delimiter, then a header
    return route, body


def is_header(frame: Any, limit: int = 1 << 20) -> bool:
    """Whether ``frame`` decodes as a msgpack map of at most ``limit`` bytes: a header of any size a
    request may have (a REQ peer's 65-tag ``library.list`` outgrew ``_peek_header``'s limits)."""
    if len(frame) > limit:
        return False
    try:
        return isinstance(msgpack.unpackb(bytes(frame), raw=False, max_bin_len=limit, max_ext_len=0,
                                          max_array_len=limit, max_map_len=limit, max_str_len=limit), dict)
    except Exception:
        return False


def peek_id(frame: Any) -> int:
    """The request id of a malformed message if its header still shows one, else 0."""
    h = _peek_header(frame)
    rid = h.get("id", 0) if isinstance(h, dict) else 0
    return rid if isinstance(rid, int) and not isinstance(rid, bool) and 0 <= rid < 1 << 63 else 0


def versioned(exc: ProtocolError, frame: Any) -> ProtocolError:
    """A 'version' error (naming both versions) when the header's protocol version is an integer
    other than ours."""
    h = _peek_header(frame)
    v = h.get("v") if isinstance(h, dict) else None
    if isinstance(v, int) and not isinstance(v, bool) and v != PROTOCOL_VERSION:
        return _VersionError(f"client speaks protocol {str(v)[:20]}, server speaks {PROTOCOL_VERSION}; update the older side")
    return exc


class _VersionError(ProtocolError):
    code = "version"


def _peek_header(frame: Any) -> Any:
    try:
        return msgpack.unpackb(bytes(frame[:65536]), raw=False, max_bin_len=1 << 16, max_ext_len=0,
                               max_array_len=64, max_map_len=64, max_str_len=4096)
    except Exception:
        return None
