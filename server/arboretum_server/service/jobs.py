"""Long jobs (decompose, import, grow, export) in worker processes, with progress and cancellation.

A handler returns a ``Job``: a worker function named ``"package.module:function"`` (imported in a fresh
``spawn`` process, called as ``function(progress=..., **kwargs)``) and a ``finish`` callback that turns
its result into the reply in the server process (committing to the session there). The ``JobRunner``
starts at most ``workers`` processes at a time and queues the rest; the server polls the workers' pipes
in its own loop, so a job never blocks another client's edits. ``cancel`` sets the job's event (the
worker's next progress call raises) and terminates the process if it has not ended a moment later.
Results come back through a multiprocessing pipe between our own processes, never from the network.
"""

from __future__ import annotations

import importlib
import logging
import multiprocessing as mp
import time
import traceback
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

from arboretum_library.errors import ArboretumError
from arboretum_library.protocol import Reply

log = logging.getLogger("arboretum.jobs")
CANCEL_GRACE_S = 2.0
PROGRESS_INTERVAL_S = 0.1


@dataclass
class Job:
    """Work to run in a worker process, and how to turn its result into a reply."""

    target: str
    """``"package.module:function"``; called as ``function(progress=callback, **kwargs)``."""
    kwargs: dict[str, Any]
    finish: Callable[[Any], Reply]
    """Runs in the server process with the worker's return value."""


class Busy(ArboretumError):
    """Too many jobs are waiting."""

    code = "busy"


class Cancelled(ArboretumError):
    """The job was cancelled."""

    code = "cancelled"


def call_target(target: str, kwargs: dict[str, Any], progress: Callable[[float, float, str], None]) -> Any:
    """Import and call ``target`` (in this process)."""
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)(progress=progress, **kwargs)


def _worker(conn, cancel, target: str, kwargs: dict[str, Any]) -> None:
    """Entry point of a worker process: run, stream progress, send ("done", result) or ("error", ...)."""
    import os
    import threading

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()
    last = [0.0]

    def progress(done: float, total: float, message: str) -> None:
        if cancel.is_set():
            raise Cancelled("cancelled by the client")
        now = time.monotonic()
        if now - last[0] >= PROGRESS_INTERVAL_S or (total > 0 and done >= total):
            last[0] = now
            conn.send(("progress", (float(done), float(total), str(message)[:200])))

    try:
        conn.send(("done", call_target(target, kwargs, progress)))
    except ArboretumError as exc:
        conn.send(("error", (exc.code, str(exc))))
    except Exception as exc:  # a bug: keep the traceback on the server, send a short line
        traceback.print_exc()
        conn.send(("error", ("internal", f"{type(exc).__name__} in {target.rsplit(':', 1)[-1]}")))
    finally:
        conn.close()


def _exit_with_parent(parent: int) -> None:
    """End this worker when the server that started it is gone (e.g. killed with SIGKILL)."""
    import os

    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(1)


@dataclass
class _Running:
    key: Hashable
    job: Job
    process: Any
    conn: Any
    cancel: Any
    cancelled_at: float | None = None
    events: list = field(default_factory=list)


class JobRunner:
    """Worker processes for jobs, keyed by whatever the caller uses (e.g. (peer, request id))."""

    def __init__(self, workers: int = 2, max_queued: int = 64) -> None:
        self._ctx = mp.get_context("spawn")
        self.workers = max(1, workers)
        self.max_queued = max_queued
        self._queue: deque[tuple[Hashable, Job]] = deque()
        self._running: dict[Hashable, _Running] = {}
        self._pending_cancel: list[Hashable] = []
        self._started: list[Hashable] = []

    def submit(self, key: Hashable, job: Job) -> None:
        """Start ``job`` now or queue it; ``Busy`` when ``max_queued`` jobs already wait."""
        if len(self._queue) >= self.max_queued:
            raise Busy(f"{len(self._queue)} jobs are already waiting; try again later")
        self._queue.append((key, job))
        self._start_queued()

    def _start_queued(self, note: bool = False) -> None:
        """Start queued jobs while workers are free; with ``note``, ``poll`` then reports each as a
        'starting' progress event (a spawned worker takes a second or more before its first own event,
        and the client's timeout runs meanwhile)."""
        while self._queue and len(self._running) < self.workers:
            key, job = self._queue.popleft()
            if note:
                self._started.append(key)
            recv, send = self._ctx.Pipe(duplex=False)
            cancel = self._ctx.Event()
            p = self._ctx.Process(target=_worker, args=(send, cancel, job.target, job.kwargs), daemon=True)
            p.start()
            send.close()
            self._running[key] = _Running(key, job, p, recv, cancel)

    def cancel(self, key: Hashable) -> bool:
        """Cancel job ``key``; False if there is no such job. Its end comes out of ``poll``."""
        for i, (k, _) in enumerate(self._queue):
            if k == key:
                del self._queue[i]
                self._pending_cancel.append(key)
                return True
        r = self._running.get(key)
        if r is None:
            return False
        r.cancel.set()
        r.cancelled_at = r.cancelled_at or time.monotonic()
        return True

    def rekey(self, old: Hashable, new: Hashable) -> bool:
        """Deliver job ``old``'s events under ``new``, whether it runs or still waits in the queue."""
        self._started = [new if k == old else k for k in self._started]
        if old in self._running:
            r = self._running.pop(old)
            r.key = new
            self._running[new] = r
            return True
        for i, (k, job) in enumerate(self._queue):
            if k == old:
                self._queue[i] = (new, job)
                return True
        return False

    def waiting(self) -> list[Hashable]:
        """Keys of the queued jobs, first to start first."""
        return [k for k, _ in self._queue]

    def keys(self) -> list[Hashable]:
        return list(self._running) + [k for k, _ in self._queue]

    def fds(self) -> list[int]:
        """File descriptors to poll for job events."""
        return [r.conn.fileno() for r in self._running.values()]

    def poll(self) -> list[tuple[Hashable, str, Any, Job | None]]:
        """Events ready now: (key, 'progress', (done, total, msg), job), (key, 'done', result, job) or
        (key, 'error', (code, message), job)."""
        out: list[tuple[Hashable, str, Any, Job | None]] = [
            (k, "error", ("cancelled", "cancelled by the client"), None) for k in self._pending_cancel]
        self._pending_cancel = []
        out += [(k, "progress", (0.0, 0.0, "starting"), self._running[k].job) for k in self._started if k in self._running]
        self._started = []
        for key, r in list(self._running.items()):
            ended = self._drain(r, out)
            if not ended and r.cancelled_at and time.monotonic() - r.cancelled_at > CANCEL_GRACE_S:
                r.process.terminate()
                out.append((key, "error", ("cancelled", "cancelled by the client"), r.job))
                ended = True
            if not ended and not r.process.is_alive() and not r.conn.poll():
                out.append((key, "error", ("internal", f"worker process died (exit code {r.process.exitcode})"), r.job))
                ended = True
            if ended:
                self._reap(key)
        self._start_queued(note=True)
        return out

    def _drain(self, r: _Running, out: list) -> bool:
        try:
            while r.conn.poll():
                kind, payload = r.conn.recv()
                out.append((r.key, kind, payload, r.job))
                if kind in ("done", "error"):
                    return True
        except (EOFError, OSError):
            if r.process.is_alive():
                r.process.join(0.5)
            out.append((r.key, "error", ("internal", f"worker process died (exit code {r.process.exitcode})"), r.job))
            return True
        except Exception as exc:  # a result that cannot be read back: a bug, never the server's end
            log.error("job %s: unreadable result", r.job.target, exc_info=exc)
            r.process.kill()
            out.append((r.key, "error", ("internal", f"unreadable result from {r.job.target.rsplit(':', 1)[-1]}"), r.job))
            return True
        return False

    def _reap(self, key: Hashable) -> None:
        r = self._running.pop(key)
        r.conn.close()
        r.process.join(1.0)
        if r.process.is_alive():
            r.process.kill()
            r.process.join(1.0)

    def shutdown(self) -> None:
        """Stop every job now."""
        self._queue.clear()
        for r in self._running.values():
            r.process.kill()
        for key in list(self._running):
            self._reap(key)
