"""The server's loop-thread bookkeeping without a socket: flow control (``service.flow``) and request
envelopes (``service.frames``)."""

from __future__ import annotations

from dataclasses import dataclass

import msgpack

from arboretum_library import protocol as P
from arboretum_library.errors import ProtocolError
from arboretum_library.wire import PROTOCOL_VERSION
from arboretum_server.service.flow import SendBudget
from arboretum_server.service.frames import is_header, peek_id, split_route, versioned


@dataclass
class FakeTracker:
    """Stands in for ``zmq.MessageTracker``: ``done`` once ZeroMQ has written the message."""

    done: bool = False


def test_a_peer_with_nothing_queued_always_gets_its_next_reply():
    b = SendBudget(per_peer=100, total=150)
    assert b.admits(b"a", 10_000)  # over both bounds, but nothing is queued for a
    t = FakeTracker()
    b.add(b"a", t, 10_000)
    assert not b.admits(b"a", 1) and b.held(b"a") == 10_000 and b.queued == 10_000
    assert b.admits(b"b", 1)  # b has nothing queued: admitted although the total is exceeded
    t.done = True
    assert b.admits(b"a", 100) and b.held(b"a") == 0 and b.queued == 0  # released when asked


def test_the_per_peer_and_total_bounds():
    b = SendBudget(per_peer=100, total=150)
    trackers = [FakeTracker() for _ in range(3)]
    b.add(b"a", trackers[0], 60)
    assert b.admits(b"a", 40) and not b.admits(b"a", 41)  # 60 + 40 <= 100 < 60 + 41
    b.add(b"b", trackers[1], 60)
    assert b.admits(b"b", 30) and not b.admits(b"b", 31)  # 120 + 30 <= 150 < 120 + 31 in all
    b.add(b"b", trackers[2], 30)
    trackers[1].done = True  # the older of b's two messages is written; the newer still holds 30
    b.release()
    assert (b.held(b"a"), b.held(b"b"), b.queued) == (60, 30, 90)
    trackers[0].done = trackers[2].done = True
    b.release()
    assert (b.held(b"a"), b.held(b"b"), b.queued) == (0, 0, 0) and not b._pending


def test_a_dealer_and_a_req_envelope():
    header, arrays = P.to_frames(P.LibraryGet(id="ex-0"), 7), [b"raw"]
    assert split_route([b"id"]) is None and split_route([]) is None
    assert split_route([b"id", *header]) == ((b"id",), list(header))
    assert split_route([b"id", b"", *header, *arrays]) == ((b"id", b""), [*header, *arrays])
    # an empty first frame not followed by a header is a (malformed) message, not a REQ delimiter
    assert split_route([b"id", b"", b"\xc1"]) == ((b"id",), [b"", b"\xc1"])
    big = msgpack.packb({"type": "library.list", "tags": [f"t{i}" for i in range(5000)]})
    assert is_header(big) and not is_header(big, limit=len(big) - 1) and not is_header(msgpack.packb([1]))


def test_a_malformed_header_still_gives_its_id_and_version():
    assert peek_id(msgpack.packb({"id": 42, "type": "nonsense"})) == 42
    for rid in (-1, 1 << 63, True, "42", 1.5):
        assert peek_id(msgpack.packb({"id": rid})) == 0
    assert peek_id(b"\xc1 not msgpack") == 0 and peek_id(msgpack.packb([42])) == 0
    err = ProtocolError("unknown request type")
    old = versioned(err, msgpack.packb({"v": PROTOCOL_VERSION + 1, "id": 1}))
    assert old.code == "version" and f"client speaks protocol {PROTOCOL_VERSION + 1}" in str(old)
    assert f"server speaks {PROTOCOL_VERSION}" in str(old)
    assert versioned(err, msgpack.packb({"v": PROTOCOL_VERSION})) is err
    assert versioned(err, msgpack.packb({"v": True})) is err and versioned(err, b"\xc1") is err
