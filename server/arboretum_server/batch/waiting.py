"""Waiting for a build's futures while watching the cluster: a scheduler without workers is reported.

``--scheduler`` may name a scheduler whose workers are not started yet (or have all died): tasks then
wait without end. ``completed`` yields futures as they finish and, each second nothing does, asks the
scheduler how many workers it has; with none, the status line says so (``Waiting``), and after
``worker_timeout`` seconds without a worker the build gives up with an ``InputError``. A LocalCluster
has no worker only while its nanny restarts a killed one: the status line says that, with no hint to
start workers (``worker_timeout`` is refused without ``--scheduler``, ``BuildOptions``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import Any

from arboretum_library.errors import InputError
from arboretum_library.progress import ProgressFn

POLL_S = 1.0
"""Seconds between looks at the scheduler while no task finishes."""
TICK_S = 0.05
"""Seconds between looks for finished futures (``as_completed`` itself polls every 0.1 s)."""


class Waiting:
    """Tells the user (``progress``) when the cluster has no worker; see the module doc. ``address``: the
    ``--scheduler`` address, None for the build's own LocalCluster."""

    def __init__(self, client: Any, address: str | None, options: Any, progress: ProgressFn,
                 status: Callable[[int, int], str]) -> None:
        self.client, self.address, self.options, self.progress = client, address, options, progress
        self.status = status
        """The status line when workers are there, from (scans done, scans in all)."""
        self.since: float | None = None
        self.done, self.total = 0, 1

    def message(self) -> str:
        if self.address is None:
            return "waiting: the local cluster has 0 workers (a worker process is being restarted)"
        return (f"waiting: the Dask scheduler at {self.address} has 0 workers (start some: "
                f"dask worker {self.address})")

    def check(self) -> None:
        """Look at the worker count; report none, or raise once ``worker_timeout`` has passed."""
        try:
            n = len(self.client.nthreads())
        except OSError:  # the scheduler is unreachable right now: the next look will tell
            return
        if n:
            if self.since is not None:  # workers came: say so before the first result
                self.progress(self.done, self.total, self.status(self.done, self.total))
            self.since = None
            return
        now = time.monotonic()
        self.since = self.since if self.since is not None else now
        self.progress(self.done, self.total, self.message())
        limit = self.options.worker_timeout
        if limit is not None and now - self.since >= limit:
            raise InputError(f"--scheduler {self.address}: no Dask worker joined in {limit:g} s "
                             f"(start some: dask worker {self.address})")


def completed(futures: list, waiting: Waiting) -> Iterator[Any]:
    """``futures`` as they finish (``distributed.as_completed``), calling ``waiting.check()`` at the start
    and whenever none finished for ``POLL_S`` seconds. Ctrl-C stops the wait."""
    from distributed import as_completed

    ready = as_completed(futures)
    waiting.total = len(futures)
    waiting.check()
    last = time.monotonic()
    while not ready.is_empty():
        if not ready.has_ready():
            time.sleep(TICK_S)
            if time.monotonic() - last >= POLL_S:
                waiting.check()
                last = time.monotonic()
            continue
        for fut in ready.next_batch(block=False):
            waiting.done += 1
            yield fut
        last = time.monotonic()
