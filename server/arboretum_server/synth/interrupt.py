"""Ctrl-C around the numba kernels of the guiding-vector model.

Compiled code does not stop for a signal: Python's SIGINT handler runs when a kernel next calls into
Python, which numba does while converting arguments and results. A ``KeyboardInterrupt`` raised there
comes out as numba's ``SystemError`` ("... returned a result with an exception set") or, inside the
Yao-graph kernels, as a segmentation fault. ``interruptible`` (``arboretum_library.atomic``, shared
with the atomic file writers) therefore only notes a Ctrl-C while a kernel runs and raises
``KeyboardInterrupt`` once it has returned: Ctrl-C then takes effect after at most one kernel call
(well under a second per call for the presets' 60,000-node graphs).
"""

from __future__ import annotations

from arboretum_library.atomic import interruptible

__all__ = ["interruptible"]
