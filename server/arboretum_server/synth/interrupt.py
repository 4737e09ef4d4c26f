"""Ctrl-C around the numba kernels of the guiding-vector model.

Compiled code does not stop for a signal: Python's SIGINT handler runs when a kernel next calls into
Python, which numba does while converting arguments and results. A ``KeyboardInterrupt`` raised there
comes out as numba's ``SystemError`` ("... returned a result with an exception set") or, inside the
Yao-graph kernels, as a segmentation fault. ``interruptible`` therefore only notes a Ctrl-C while a
kernel runs and raises ``KeyboardInterrupt`` once it has returned: Ctrl-C then takes effect after at
most one kernel call (well under a second per call for the presets' 60,000-node graphs).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def interruptible() -> Iterator[None]:
    """Defer Ctrl-C (SIGINT) to the end of the block, then raise ``KeyboardInterrupt``.

    Only when Python's default handler is installed and this is the main thread (the only thread that
    may change a handler); otherwise the block runs unchanged.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):  # fmt: skip
        yield
        return
    caught: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    except BaseException:
        if caught:
            raise KeyboardInterrupt from None
        raise
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if caught:
        raise KeyboardInterrupt
