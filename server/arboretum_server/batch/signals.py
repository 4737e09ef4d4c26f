"""Signals during ``library build``: Ctrl-C reaches the client alone, and SIGTERM stops a build as Ctrl-C does.

A LocalCluster's worker processes start with SIGINT blocked (``sigint_waits``) and then ignore it, so a
Ctrl-C in the terminal, which reaches the whole process group, is handled by the client alone (it cancels
the tasks and shuts the cluster down). The command turns SIGTERM into ``Terminated`` (``sigterm_stops``).
Either one that comes while the cluster starts waits until it is up and is then raised
(``sigint_waits``, ``sigterm_waits``).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

from arboretum_library.signals import held


@contextlib.contextmanager
def sigint_waits() -> Iterator[None]:
    """Hold a Ctrl-C while the block starts the LocalCluster and its client, and raise it
    (``KeyboardInterrupt``) when the block ends: raised inside the start, it would leave worker processes
    behind. SIGINT is blocked in this thread for the block (``pthread_sigmask``), so the threads the start
    creates (the cluster's event loop, the nannies' process starters) and the worker processes they spawn
    inherit it blocked: a Ctrl-C in the terminal, which reaches the whole process group, stays pending in a
    worker, unseen, until its preload ignores SIGINT (``tasks.dask_setup``), and only the client handles it
    (cancel, shut the cluster down) instead of every worker printing a KeyboardInterrupt traceback.
    SIGINT ignored (``SIG_IGN``) for the block, as before session 19, lost a Ctrl-C then; blocked in this
    thread as well it was still lost (10 of 10): the client's 2 other threads at the start do not block it,
    and the kernel gives it to one of them, which discards it. Here a handler notes it, whichever thread
    takes it. Outside the main thread a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with held(signal.SIGINT) as got:
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # a pending Ctrl-C is noted in ``got`` here
    if got:
        raise KeyboardInterrupt


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a service manager) under ``sigterm_stops``: the build stops as on Ctrl-C (tasks
    cancelled, the cluster shut down, what was stored kept); ``arboretum library build`` exits 143."""


_TERM = {"starting": False, "pending": False}
"""``sigterm_stops``'s state: a SIGTERM while the LocalCluster starts waits until it is up (``pending``)."""


@contextlib.contextmanager
def sigterm_stops() -> Iterator[None]:
    """Raise ``Terminated`` in the main thread on SIGTERM, once: a second one while the workers shut down
    is ignored, so the shutdown completes (killed mid-way, the client left its workers' semaphores to
    Python's "leaked semaphore objects" warning). While the LocalCluster starts it waits until the
    cluster is up (``sigterm_waits``). Outside the main thread a no-op. Used by the command, not by
    ``build_library``: a library function leaves the process's signals alone."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(*_) -> None:
        if _TERM["starting"]:
            _TERM["pending"] = True
            return
        signal.signal(signal.SIGTERM, lambda *_: None)  # a Python handler: children do not inherit it
        raise Terminated

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        _TERM.update(starting=False, pending=False)


@contextlib.contextmanager
def sigterm_waits() -> Iterator[None]:
    """Hold a SIGTERM (under ``sigterm_stops``) while the block starts the LocalCluster, and raise it
    after: raised inside the start, it would leave worker processes behind."""
    _TERM["starting"] = True
    try:
        yield
    finally:
        _TERM["starting"] = False
    if _TERM["pending"]:
        _TERM["pending"] = False
        signal.signal(signal.SIGTERM, lambda *_: None)
        raise Terminated
