"""The network worker: one thread owns the ``SessionPort``; the frame loop never waits on it.

The frame loop ``submit``s a call (a name, a function of the port, a callback); the worker runs calls
in order and posts ``Done`` (result or error) and ``Progress`` records to a queue that the frame loop
``drain``s once per frame, running callbacks on the main thread, so slow work (file reads and writes)
belongs in the call, never in ``on_done``. A ``USER_ERRORS`` failure raised by an ``on_done`` callback
still goes to the job's ``on_error`` (a guard). The port (and its sockets) is only ever touched by the
worker thread.
"""

from __future__ import annotations

import itertools
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from arboretum_library.errors import ArboretumError

from .session_port import SessionPort

USER_ERRORS = (ArboretumError, OSError)
"""Failures a user can cause (a bad file, an unwritable folder, a refused request): a status line,
never an exception in the frame loop. Anything else is a bug and keeps its traceback."""


@dataclass(frozen=True)
class Job:
    """One submitted call."""

    id: int
    name: str
    """What it does, for people ('grow', 'add example', ...)."""
    call: Callable[..., Any]
    """call(port, progress) -> result, run on the worker thread."""
    on_done: Callable[[Any], None] | None = None
    """Run on the main thread with the result."""
    on_error: Callable[[BaseException], None] | None = None


@dataclass(frozen=True)
class Done:
    job: Job
    result: Any = None
    error: BaseException | None = None


@dataclass(frozen=True)
class Progress:
    job: Job
    done: float
    total: float
    message: str = ""


@dataclass
class JobStatus:
    """What the UI shows for a running job."""

    name: str
    fraction: float | None = None
    """0..1, or None while the total is unknown."""
    message: str = ""
    extra: dict = field(default_factory=dict)


class Worker:
    """A daemon thread running port calls in order; results come back through ``drain``."""

    def __init__(self, port_factory: Callable[[], SessionPort]) -> None:
        self._factory = port_factory
        self._inbox: queue.Queue[Job | None] = queue.Queue()
        self._outbox: queue.Queue[Done | Progress] = queue.Queue()
        self._ids = itertools.count(1)
        self.running: dict[int, JobStatus] = {}
        """Jobs submitted and not yet drained as done (main thread only)."""
        self.port: SessionPort | None = None
        self._thread = threading.Thread(target=self._loop, name="arboretum-net", daemon=True)
        self._thread.start()

    def submit(self, name: str, call: Callable[..., Any], on_done: Callable[[Any], None] | None = None,
               on_error: Callable[[BaseException], None] | None = None) -> int:
        """Queue ``call(port, progress)``; returns the job id at once."""
        job = Job(next(self._ids), name, call, on_done, on_error)
        self.running[job.id] = JobStatus(name)
        self._inbox.put(job)
        return job.id

    def _loop(self) -> None:
        try:
            self.port = self._factory()
        except BaseException as exc:  # reported for every job below
            self.port, failure = None, exc
        else:
            failure = None
        while (job := self._inbox.get()) is not None:
            if failure is not None:
                self._outbox.put(Done(job, error=failure))
                continue

            def progress(done: float, total: float, message: str = "", job: Job = job) -> None:
                self._outbox.put(Progress(job, float(done), float(total), message))

            try:
                self._outbox.put(Done(job, result=job.call(self.port, progress)))
            except Exception as exc:  # a failed call is a reply, never the end of the worker
                self._outbox.put(Done(job, error=exc))
        if self.port is not None:
            self.port.close()

    def drain(self, limit: int = 64) -> list[Done]:
        """Run callbacks of finished jobs (main thread); never blocks. Returns what finished."""
        finished = []
        for _ in range(limit):
            try:
                item = self._outbox.get_nowait()
            except queue.Empty:
                break
            if isinstance(item, Progress):
                status = self.running.get(item.job.id)
                if status is not None:
                    status.fraction = item.done / item.total if item.total > 0 else None
                    status.message = item.message
                continue
            self.running.pop(item.job.id, None)
            finished.append(item)
            error = item.error
            if error is None and item.job.on_done is not None:
                try:
                    item.job.on_done(item.result)
                except USER_ERRORS as exc:  # a guard: a user's mistake is a status line, not a crash
                    error = exc
            if error is not None and item.job.on_error is not None:
                item.job.on_error(error)
        return finished

    def idle(self) -> bool:
        return not self.running

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """For scripts and tests only (never in the frame loop): drain until no job runs."""
        import time

        end = time.monotonic() + timeout
        while self.running and time.monotonic() < end:
            self.drain()
            time.sleep(0.002)
        self.drain()
        return not self.running

    def close(self, timeout: float = 5.0) -> None:
        self._inbox.put(None)
        self._thread.join(timeout)
