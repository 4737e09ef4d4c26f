"""How much the server keeps for each client and queues to it: remembered replies and the send budget.

``ReplyCache`` answers a retried request that changes something from its kept reply (or with
``duplicate`` once that reply was dropped), so it never runs twice. ``SendBudget`` bounds the bytes
handed to ZeroMQ for peers that do not read their replies: 64 MB per peer and 512 MB in all, except
that a peer with nothing queued always gets its next reply.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from typing import Any

import zmq

Key = tuple[Any, int, str]
"""(client token, "" for clients without one, request id, request type)."""

REPEATABLE = frozenset({"ping", "hello", "cancel", "library.list", "library.search", "library.get", "session.list",
                        "session.get", "session.hbl", "refine.points", "assembly.recognize"})
"""Requests that change nothing: their replies are not cached, a retry simply runs again."""
REPLY_CACHE = 4096
"""Replies kept for answering retried requests (at most this many ...)."""
REPLY_CACHE_BYTES = 128 << 20
"""... and at most this many bytes; older ones are dropped first."""
DONE_PER_CLIENT = 32
"""Keys of answered requests remembered per client, even when their replies were dropped ..."""
DONE_CLIENTS = 4096
"""... for this many most recently answered clients."""
PEER_QUEUE_BYTES = 64 << 20
"""Bytes queued for one peer at most (a reply beyond it is dropped unless nothing is queued) ..."""
QUEUE_BYTES = 512 << 20
"""... and for all peers together."""
TRACK_BYTES = 8 << 10
"""Messages this large or larger count against the budget; smaller ones only against SNDHWM."""


class ReplyCache:
    """Replies of answered requests by ``Key``, so a retry is answered, never run twice.

    Reply frames are kept within ``max_replies`` and ``max_bytes`` over all clients (oldest dropped
    first). Separately each client's last ``per_client`` answered keys are remembered (for the last
    ``clients`` clients), so a retry whose reply another client's traffic pushed out is still known
    as done: ``get`` then says ``True`` and the caller answers ``duplicate`` instead of running it.
    """

    def __init__(self, max_replies: int = REPLY_CACHE, max_bytes: int = REPLY_CACHE_BYTES,
                 per_client: int = DONE_PER_CLIENT, clients: int = DONE_CLIENTS) -> None:
        self.max_replies, self.max_bytes, self.per_client, self.clients = max_replies, max_bytes, per_client, clients
        self._frames: OrderedDict[Key, tuple[list, int]] = OrderedDict()
        self._done: OrderedDict[Any, OrderedDict[tuple[int, str], None]] = OrderedDict()
        self.bytes = 0

    def get(self, key: Key) -> list | bool:
        """The cached frames of ``key``; True if it was answered but its reply dropped; else False."""
        hit = self._frames.get(key)
        if hit is not None:
            return hit[0]
        done = self._done.get(key[0])
        return done is not None and key[1:] in done

    def put(self, key: Key, frames: list) -> None:
        size = sum(len(f) for f in frames)
        self._frames[key] = (frames, size)
        self.bytes += size
        while len(self._frames) > self.max_replies or self.bytes > self.max_bytes:
            self.bytes -= self._frames.popitem(last=False)[1][1]
        done = self._done.pop(key[0], None) or OrderedDict()
        self._done[key[0]] = done  # most recently answered client last
        done[key[1:]] = None
        while len(done) > self.per_client:
            done.popitem(last=False)
        while len(self._done) > self.clients:
            self._done.popitem(last=False)


class SendBudget:
    """Bytes handed to ZeroMQ and not yet written out (or dropped), per peer and in all, from the
    trackers of zero-copy sends."""

    def __init__(self, per_peer: int = PEER_QUEUE_BYTES, total: int = QUEUE_BYTES) -> None:
        self.per_peer, self.total = per_peer, total
        self._pending: dict[bytes, deque[tuple[zmq.MessageTracker, int]]] = {}
        self._held: dict[bytes, int] = {}
        self.queued = 0

    def admits(self, peer: bytes, size: int) -> bool:
        """Whether a message of ``size`` bytes for ``peer`` may be queued now."""
        self.release(peer)
        held = self._held.get(peer, 0)
        return held == 0 or (held + size <= self.per_peer and self.queued + size <= self.total)

    def add(self, peer: bytes, tracker: zmq.MessageTracker, size: int) -> None:
        self._pending.setdefault(peer, deque()).append((tracker, size))
        self._held[peer] = self._held.get(peer, 0) + size
        self.queued += size

    def release(self, peer: bytes | None = None) -> None:
        """Forget messages ZeroMQ is done with (of ``peer``, or of every peer)."""
        for p in [peer] if peer is not None else list(self._pending):
            q = self._pending.get(p)
            while q and q[0][0].done:
                size = q.popleft()[1]
                self._held[p] -= size
                self.queued -= size
            if q is not None and not q:
                del self._pending[p], self._held[p]

    def held(self, peer: bytes) -> int:
        return self._held.get(peer, 0)
