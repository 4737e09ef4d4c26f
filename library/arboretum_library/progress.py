"""Progress for long work: a callback type, and a status line on a terminal.

Algorithms take an optional ``progress: ProgressFn`` and call it with (done, total, message); they never
print. The CLI passes ``StatusLine``; the server turns the calls into progress events on the wire.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

ProgressFn = Callable[[float, float, str], None]


def no_progress(done: float, total: float, message: str) -> None:
    """A progress callback that does nothing."""


class StatusLine:
    """Draws ``message [####....] 42%`` on one line of ``stream`` (stderr), at most 10 times a second."""

    def __init__(self, stream: TextIO | None = None, width: int = 30) -> None:
        self.stream = stream or sys.stderr
        self.width = width
        self._last = 0.0
        self._tty = self.stream.isatty()

    def __call__(self, done: float, total: float, message: str) -> None:
        now = time.monotonic()
        final = total > 0 and done >= total
        if not final and now - self._last < 0.1:
            return
        self._last = now
        frac = min(max(done / total, 0.0), 1.0) if total > 0 else 0.0
        bar = "#" * int(frac * self.width)
        line = f"{message} [{bar:<{self.width}}] {frac * 100:3.0f}%"
        if self._tty:
            self.stream.write("\r" + line + ("\n" if final else ""))
        elif final:
            self.stream.write(line + "\n")
        self.stream.flush()
