"""The one place that owns the ROUTER socket: receive, parse, dispatch, reply; run the job pipes.

One thread polls the socket and the job workers' pipes. A request is parsed into its typed message
(anything malformed gets an ``Error`` reply, or is dropped when not even an id can be read back), handled
inline when quick, or handed to the ``JobRunner`` when its handler returns a ``Job``; job progress goes
back to the requesting peer as ``Progress`` events. Requests are keyed by (origin, id, type), the origin
being the header's "client" token (the same in all retries of a ``Remote``), or one shared origin for
clients without one (protocol 1's lazy-pirate retries come from a new socket): a
retried job answers the socket of its latest retry, and a retried request that changes something is
answered from the ``ReplyCache``, never run twice. ``SendBudget`` bounds the bytes queued for peers
that do not read their replies (both in ``flow``). REQ peers work too (``frames`` keeps their empty
delimiter frame as routing).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import zmq

from arboretum_library import protocol as P
from arboretum_library.errors import ProtocolError
from arboretum_library.protocol_base import parse_request
from arboretum_library.wire import Limits

from .dispatch import Dispatcher, error_reply
from .flow import REPEATABLE, TRACK_BYTES, Key, ReplyCache, SendBudget
from .frames import Route, peek_id, split_route, versioned
from .jobs import Job, JobRunner

log = logging.getLogger("arboretum.server")

SNDHWM = 1000
"""Messages ZeroMQ queues for one peer at most (more are dropped)."""
QUEUED_NOTE_S = 1.0
"""While a job waits for a worker, its client gets a progress event this often (restarting its timeout)."""
POLL_MS = 50


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
        envelope = split_route(frames)
        if envelope is None:
            return
        route, body = envelope
        try:
            rid, client, req = parse_request(body, self.limits)
        except ProtocolError as exc:
            log.debug("malformed message from %r: %s", route[0], exc)
            self._send(route, peek_id(body[0]), error_reply(versioned(exc, body[0])))
            return
        except Exception as exc:  # a bug in parsing must not stop the server
            self._send(route, peek_id(body[0]), error_reply(exc, "parse"))
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
