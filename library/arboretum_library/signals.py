"""Holding signals over a stretch of work that must not be cut short.

Python runs a signal's handler in the main thread between two bytecodes, so a Ctrl-C can raise
``KeyboardInterrupt`` anywhere: while a call waits for threads it started (scipy's KD-tree ``workers``
then run on as the interpreter shuts down under them, and crash it), or after a command has stored its
work and is only printing it. ``held`` replaces the handlers for the block and gives the caller the
signals that came, to raise again (``signal.raise_signal``) or to report.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def held(*signums: int) -> Iterator[list[int]]:
    """Hold ``signums`` for the block: each that arrives is appended to the yielded list instead of handled,
    and the handlers there before are back when the block ends (on an exception too). Only the main thread
    can set handlers, and only it receives signals: elsewhere nothing is held."""
    got: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield got
        return
    previous = {s: signal.signal(s, lambda signum, frame: got.append(signum)) for s in signums}
    try:
        yield got
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
