"""The one place that owns the ROUTER socket: receive, parse, dispatch, reply; run the job pipes.

One thread polls the socket and the job workers' pipes. A request is parsed into its typed message
(anything malformed gets an ``Error`` reply, or is dropped when not even an id can be read back), handled
inline when quick, or handed to the ``JobRunner`` when its handler returns a ``Job``; job progress goes
back to the requesting peer as ``Progress`` events. Replies to recent requests are kept by request id,
so a client that timed out, reconnected and resent the same request gets the same answer and an edit
is never applied twice.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from typing import Any

import msgpack
import zmq

from arboretum_library import protocol as P
from arboretum_library.errors import ProtocolError
from arboretum_library.wire import Limits

from .dispatch import Dispatcher, error_reply
from .jobs import Job, JobRunner

log = logging.getLogger("arboretum.server")
REPLY_CACHE = 4096
"""Replies kept for answering retried requests (at most this many ...)."""
REPLY_CACHE_BYTES = 256 << 20
"""... and at most this many bytes; older ones are dropped first."""
POLL_MS = 50


class Server:
    """A ROUTER socket bound to ``endpoint`` serving ``dispatcher``'s handlers."""

    def __init__(self, dispatcher: Dispatcher, endpoint: str, *, jobs: JobRunner | None = None,
                 limits: Limits = Limits(max_array_bytes=1 << 29, max_message_bytes=1 << 30),
                 curve_secret: tuple[bytes, bytes] | None = None, zctx: zmq.Context | None = None) -> None:
        self.dispatcher = dispatcher
        self.jobs = jobs or JobRunner()
        self.limits = limits
        self.zctx = zctx or zmq.Context.instance()
        self.sock = self.zctx.socket(zmq.ROUTER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.ROUTER_HANDOVER, 1)
        self.sock.setsockopt(zmq.MAXMSGSIZE, limits.max_message_bytes)
        self.sock.setsockopt(zmq.SNDHWM, 10000)
        if curve_secret is not None:
            self.sock.curve_server = True
            self.sock.curve_publickey, self.sock.curve_secretkey = curve_secret
        if endpoint.endswith(":0"):
            endpoint = endpoint[:-2] + ":*"
        self.sock.bind(endpoint)
        self.endpoint = self.sock.getsockopt_string(zmq.LAST_ENDPOINT)
        self._replies: OrderedDict[tuple[int, str], tuple[list, int]] = OrderedDict()
        self._cached_bytes = 0
        self._jobs_of: dict[tuple[int, str], tuple[bytes, int]] = {}
        self.stop_event = threading.Event()
        self.handled = 0

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

    # -- requests ------------------------------------------------------------------------------
    def _on_frames(self, frames: list) -> None:
        if len(frames) < 2:
            return
        peer, body = bytes(frames[0]), frames[1:]
        try:
            rid, req = P.parse(body, self.limits)
        except ProtocolError as exc:
            rid = _peek_id(body[0])
            log.debug("malformed message from %r: %s", peer, exc)
            self._send(peer, rid, error_reply(_versioned(exc, body[0])))
            return
        except Exception as exc:  # a bug in parsing must not stop the server
            self._send(peer, _peek_id(body[0]), error_reply(exc, "parse"))
            return
        self.handled += 1
        try:
            self._on_request(peer, rid, req)
        except Exception as exc:  # never let one request take the loop down
            self._send(peer, rid, error_reply(exc, req.TYPE))

    def _on_request(self, peer: bytes, rid: int, req: P.Msg) -> None:
        key = (rid, req.TYPE)
        if rid and key in self._replies:
            self._send_frames(peer, self._replies[key][0])
            return
        if rid and key in self._jobs_of:  # a retry of a running job: answer the new socket
            old_peer, _ = self._jobs_of[key]
            self.jobs.rekey((old_peer, rid), (peer, rid))
            self._jobs_of[key] = (peer, rid)
            return
        if isinstance(req, P.Cancel):
            ok = self.jobs.cancel((peer, req.request))
            self._send(peer, rid, P.Ack(detail="cancelling" if ok else f"no running job {req.request}"))
            return
        out = self.dispatcher.handle(req)
        if isinstance(out, Job):
            self.jobs.submit((peer, rid), out)
            self._jobs_of[key] = (peer, rid)
            return
        self._reply(peer, rid, req.TYPE, out)

    def _on_job_event(self, key: Any, kind: str, payload: Any, job: Job | None) -> None:
        peer, rid = key
        if kind == "progress":
            done, total, message = payload
            self._send(peer, rid, P.Progress(done=done, total=total, message=message))
            return
        req_type = next((t for (i, t), v in self._jobs_of.items() if v == key), "")
        self._jobs_of.pop((rid, req_type), None)
        if kind == "done" and job is not None:
            reply = self.dispatcher.finish(job, payload, req_type or "job")
        else:
            code, message = payload
            reply = P.Error(code=code, message=message)
        self._reply(peer, rid, req_type, reply)

    # -- sending -------------------------------------------------------------------------------
    def _reply(self, peer: bytes, rid: int, req_type: str, reply: P.Msg) -> None:
        try:
            frames = P.to_frames(reply, rid)
        except Exception as exc:
            frames = P.to_frames(error_reply(exc, "encode reply"), rid)
        if rid and req_type:
            size = sum(len(f) for f in frames)
            self._replies[(rid, req_type)] = (frames, size)
            self._cached_bytes += size
            while len(self._replies) > REPLY_CACHE or self._cached_bytes > REPLY_CACHE_BYTES:
                self._cached_bytes -= self._replies.popitem(last=False)[1][1]
        self._send_frames(peer, frames)

    def _send(self, peer: bytes, rid: int, msg: P.Msg) -> None:
        self._send_frames(peer, P.to_frames(msg, rid))

    def _send_frames(self, peer: bytes, frames: list) -> None:
        try:
            self.sock.send_multipart([peer, *frames], zmq.NOBLOCK, copy=False)
        except zmq.ZMQError:  # peer gone or its queue full: it will retry or has left
            pass


def _peek_id(frame: Any) -> int:
    """The request id of a malformed message if its header still shows one, else 0."""
    try:
        h = msgpack.unpackb(bytes(frame[:65536]), raw=False, max_bin_len=0, max_ext_len=0,
                            max_array_len=64, max_map_len=64, max_str_len=4096)
        rid = h.get("id", 0) if isinstance(h, dict) else 0
        return rid if isinstance(rid, int) and not isinstance(rid, bool) and 0 <= rid < 1 << 63 else 0
    except Exception:
        return 0


class _VersionError(ProtocolError):
    code = "version"


def _versioned(exc: ProtocolError, frame: Any) -> ProtocolError:
    """A 'version' error (naming both versions) when the header's protocol version is not ours."""
    try:
        h = msgpack.unpackb(bytes(frame[:65536]), raw=False, max_bin_len=0, max_ext_len=0,
                            max_array_len=64, max_map_len=64, max_str_len=4096)
    except Exception:
        return exc
    from arboretum_library.wire import PROTOCOL_VERSION

    if isinstance(h, dict) and "v" in h and h["v"] != PROTOCOL_VERSION:
        return _VersionError(f"client speaks protocol {str(h['v'])[:20]}, server speaks {PROTOCOL_VERSION}; update the older side")
    return exc
