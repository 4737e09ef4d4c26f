"""Signals during ``library build``: Ctrl-C reaches the client alone, and SIGTERM stops a build as Ctrl-C does.

A LocalCluster's worker processes start with SIGINT ignored (``workers_ignore_sigint``), so a Ctrl-C in
the terminal, which reaches the whole process group, is handled by the client alone (it cancels the tasks
and shuts the cluster down). The command turns SIGTERM into ``Terminated`` (``sigterm_stops``); one that
comes while the cluster starts waits until it is up (``sigterm_waits``).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def workers_ignore_sigint() -> Iterator[None]:
    """Ignore SIGINT while LocalCluster starts its worker processes, which keep ignoring it (an ignored
    signal stays ignored across exec and Python then installs no KeyboardInterrupt handler): Ctrl-C in
    the terminal reaches the whole process group, and only the client should handle it (cancel, shut the
    cluster down) instead of every worker printing a KeyboardInterrupt traceback. A Ctrl-C during the
    few seconds of start-up is lost. Outside the main thread (where signals cannot be set) a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


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
