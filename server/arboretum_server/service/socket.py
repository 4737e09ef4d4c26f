"""The one place that owns the ROUTER socket: receive, parse, dispatch, reply; run the job pipes.

One thread polls the socket and the job workers' pipes. A request is parsed into its typed message
(anything malformed gets an ``Error`` reply, or is dropped when not even an id can be read back), handled
inline when quick, or handed to the ``JobRunner`` when its handler returns a ``Job``; job progress goes
back to the requesting peer as ``Progress`` events. Requests are keyed by (origin, id, type), the origin
being the header's "client" token (the same in all retries of a ``Remote``), or one shared origin for
clients without one (protocol 1's lazy-pirate retries come from a new socket): a
retried job answers the socket of its latest retry, and a retried request that changes something is
answered from the ``ReplyCache``, never run twice. ``SendBudget`` bounds the bytes queued for peers
that do not read their replies. REQ peers work too (their empty delimiter frame is kept as routing).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict, deque
from typing import Any

import msgpack
import zmq

from arboretum_library import protocol as P
from arboretum_library.errors import ProtocolError
from arboretum_library.protocol_base import parse_request
from arboretum_library.wire import PROTOCOL_VERSION, Limits

from .dispatch import Dispatcher, error_reply
from .jobs import Job, JobRunner

log = logging.getLogger("arboretum.server")
Route = tuple[bytes, ...]
"""Routing frames of a peer: (identity,) for DEALER, (identity, b"") for REQ."""
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
SNDHWM = 1000
"""Messages ZeroMQ queues for one peer at most (more are dropped)."""
PEER_QUEUE_BYTES = 64 << 20
"""Bytes queued for one peer at most (a reply beyond it is dropped unless nothing is queued) ..."""
QUEUE_BYTES = 512 << 20
"""... and for all peers together."""
TRACK_BYTES = 8 << 10
"""Messages this large or larger count against the budget; smaller ones only against SNDHWM."""
QUEUED_NOTE_S = 1.0
"""While a job waits for a worker, its client gets a progress event this often (restarting its timeout)."""
POLL_MS = 50


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


class Server:
    """A ROUTER socket bound to ``endpoint`` serving ``dispatcher``'s handlers."""

    def __init__(self, dispatcher: Dispatcher, endpoint: str, *, jobs: JobRunner | None = None,
                 limits: Limits = Limits(max_array_bytes=1 << 29, max_message_bytes=1 << 30),
                 curve_secret: tuple[bytes, bytes] | None = None, zctx: zmq.Context | None = None,
                 budget: SendBudget | None = None) -> None:
        self.dispatcher = dispatcher
        self.jobs = jobs or JobRunner()
        self.limits = limits
        self.zctx = zctx or zmq.Context.instance()
        self.sock = self.zctx.socket(zmq.ROUTER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.ROUTER_HANDOVER, 1)
        self.sock.setsockopt(zmq.MAXMSGSIZE, limits.max_message_bytes)
        self.sock.setsockopt(zmq.SNDHWM, SNDHWM)
        if curve_secret is not None:
            self.sock.curve_server = True
            self.sock.curve_publickey, self.sock.curve_secretkey = curve_secret
        if endpoint.endswith(":0"):
            endpoint = endpoint[:-2] + ":*"
        self.sock.bind(endpoint)
        self.endpoint = self.sock.getsockopt_string(zmq.LAST_ENDPOINT)
        self.replies = ReplyCache()
        self.budget = budget or SendBudget()
        self._jobs: dict[Key, Route] = {}
        """Running or queued jobs (the JobRunner's keys) -> the route of the latest request for them."""
        self._noted = 0.0
        self.stop_event = threading.Event()
        self.handled = 0
        self.dropped = 0
        """Replies dropped because their peer had too many bytes queued."""

    # -- the loop ------------------------------------------------------------------------------
    def serve_forever(self) -> None:
        """Serve until ``stop_event`` is set; then stop the jobs, close the library (it belongs to this
        thread) and the socket."""
        try:
            while not self.stop_event.is_set():
                self.step(POLL_MS)
        finally:
            self.jobs.shutdown()
            self.dispatcher.ctx.close()
            self.sock.close(0)

    def step(self, timeout_ms: int) -> None:
        poller = zmq.Poller()
        poller.register(self.sock, zmq.POLLIN)
        for fd in self.jobs.fds():
            poller.register(fd, zmq.POLLIN)
        ready = dict(poller.poll(timeout_ms))
        if self.sock in ready:
            for _ in range(256):  # drain a burst, but let job events through
                try:
                    frames = self.sock.recv_multipart(zmq.NOBLOCK, copy=False)
                except zmq.Again:
                    break
                self._on_frames([f.buffer for f in frames])
        for key, kind, payload, job in self.jobs.poll():
            try:
                self._on_job_event(key, kind, payload, job)
            except Exception as exc:  # never let one job's end take the loop down
                log.error("job event %s for %r failed", kind, key, exc_info=exc)
        if time.monotonic() - self._noted >= QUEUED_NOTE_S:
            self._note_waiting()
        self.budget.release()

    # -- requests ------------------------------------------------------------------------------
    def _on_frames(self, frames: list) -> None:
        if len(frames) < 2:
            return
        route, body = (bytes(frames[0]),), frames[1:]
        if len(body) > 1 and not len(body[0]) and _is_header(body[1]):
            route, body = (route[0], b""), body[1:]  # a REQ peer: an empty delimiter, then a header
        try:
            rid, client, req = parse_request(body, self.limits)
        except ProtocolError as exc:
            log.debug("malformed message from %r: %s", route[0], exc)
            self._send(route, _peek_id(body[0]), error_reply(_versioned(exc, body[0])))
            return
        except Exception as exc:  # a bug in parsing must not stop the server
            self._send(route, _peek_id(body[0]), error_reply(exc, "parse"))
            return
        self.handled += 1
        try:
            # without a token, clients share one id space, as in protocol 1 before tokens: a retry on
            # a new socket (lazy pirate) must find its reply (use random 63-bit ids, as Remote does)
            self._on_request(route, (client, rid, req.TYPE), req)
        except Exception as exc:  # never let one request take the loop down
            self._send(route, rid, error_reply(exc, req.TYPE))

    def _on_request(self, route: Route, key: Key, req: P.Msg) -> None:
        origin, rid, _ = key
        if rid and key in self._jobs:  # a retry of a running or queued job: it answers this socket now
            self._jobs[key] = route
            self._note_waiting(key)
            return
        cached = self.replies.get(key) if rid else False
        if cached is True:
            self._send(route, rid, P.Error(code="duplicate", message=(
                f"request {rid} ({req.TYPE}) was already done; its reply is no longer kept, so it is not run again")))
            return
        if cached:
            self._send_frames(route, cached)
            return
        if isinstance(req, P.Cancel):
            job = next((k for k in self._jobs if k[:2] == (origin, req.request)), None)
            ok = job is not None and self.jobs.cancel(job)
            self._send(route, rid, P.Ack(detail="cancelling" if ok else f"no running job {req.request}"))
            return
        out = self.dispatcher.handle(req)
        if isinstance(out, Job):
            self.jobs.submit(key, out)
            self._jobs[key] = route
            return
        self._reply(route, key, out)

    def _on_job_event(self, key: Key, kind: str, payload: Any, job: Job | None) -> None:
        if kind == "progress":
            if key in self._jobs:
                done, total, message = payload
                self._send(self._jobs[key], key[1], P.Progress(done=done, total=total, message=message))
            return
        route = self._jobs.pop(key, ())  # () only if lost by a bug: still finish (commit), send nothing
        if kind == "done" and job is not None:
            reply = self.dispatcher.finish(job, payload, key[2])
        else:
            code, message = payload
            reply = P.Error(code=code, message=message)
        self._reply(route, key, reply)

    def _note_waiting(self, only: Key | None = None) -> None:
        """Tell the clients of queued jobs (or of job ``only``, if queued) that their job waits."""
        if only is None:
            self._noted = time.monotonic()
        for i, key in enumerate(self.jobs.waiting()):
            if (only is None or key == only) and key in self._jobs:
                note = f"waiting for a free worker ({i + 1} in the queue)"
                self._send(self._jobs[key], key[1], P.Progress(done=0, total=0, message=note))

    # -- sending -------------------------------------------------------------------------------
    def _reply(self, route: Route, key: Key, reply: P.Msg) -> None:
        rid = key[1]
        try:
            frames = P.to_frames(reply, rid)
        except Exception as exc:
            frames = P.to_frames(error_reply(exc, "encode reply"), rid)
        if rid and key[2] not in REPEATABLE:
            self.replies.put(key, frames)
        self._send_frames(route, frames)

    def _send(self, route: Route, rid: int, msg: P.Msg) -> None:
        self._send_frames(route, P.to_frames(msg, rid))

    def _send_frames(self, route: Route, frames: list) -> None:
        if not route:
            return
        size = sum(len(f) for f in frames)
        if not self.budget.admits(route[0], size):
            self.dropped += 1
            log.debug("dropped a %d-byte reply to %r: %d bytes already queued", size, route[0], self.budget.held(route[0]))
            return
        if size < TRACK_BYTES:  # small: copied by ZeroMQ, bounded by SNDHWM (tracking costs ~40 us)
            last = frames[-1]
        else:  # tracked: tells when ZeroMQ is done with it
            last = zmq.Frame(frames[-1], track=True, copy=False, copy_threshold=0)
        try:
            self.sock.send_multipart([*route, *frames[:-1], last], zmq.NOBLOCK, copy=False)
        except zmq.ZMQError:  # peer gone or its queue full: it will retry or has left
            return
        if size >= TRACK_BYTES:
            self.budget.add(route[0], last.tracker, size)


def _peek_id(frame: Any) -> int:
    """The request id of a malformed message if its header still shows one, else 0."""
    h = _peek_header(frame)
    rid = h.get("id", 0) if isinstance(h, dict) else 0
    return rid if isinstance(rid, int) and not isinstance(rid, bool) and 0 <= rid < 1 << 63 else 0


def _is_header(frame: Any, limit: int = 1 << 20) -> bool:
    """Whether ``frame`` decodes as a msgpack map of at most ``limit`` bytes: a header of any size a
    request may have (a REQ peer's 65-tag ``library.list`` outgrew ``_peek_header``'s limits)."""
    if len(frame) > limit:
        return False
    try:
        return isinstance(msgpack.unpackb(bytes(frame), raw=False, max_bin_len=limit, max_ext_len=0,
                                          max_array_len=limit, max_map_len=limit, max_str_len=limit), dict)
    except Exception:
        return False


def _peek_header(frame: Any) -> Any:
    try:
        return msgpack.unpackb(bytes(frame[:65536]), raw=False, max_bin_len=1 << 16, max_ext_len=0,
                               max_array_len=64, max_map_len=64, max_str_len=4096)
    except Exception:
        return None


class _VersionError(ProtocolError):
    code = "version"


def _versioned(exc: ProtocolError, frame: Any) -> ProtocolError:
    """A 'version' error (naming both versions) when the header's protocol version is an integer
    other than ours."""
    h = _peek_header(frame)
    v = h.get("v") if isinstance(h, dict) else None
    if isinstance(v, int) and not isinstance(v, bool) and v != PROTOCOL_VERSION:
        return _VersionError(f"client speaks protocol {str(v)[:20]}, server speaks {PROTOCOL_VERSION}; update the older side")
    return exc
