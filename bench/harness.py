"""What every benchmark module uses: timing by median, and one result row format.

A benchmark module ``bench/bench_NAME.py`` defines ``run() -> list[Row]``. Rows give the median of
several runs, the target the issue set (if any), and where possible a baseline measured in the same run
so the ratio means something on any machine.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any


@dataclass
class Row:
    name: str
    """What was measured, e.g. 'decompose 12k points'."""
    median: float
    """Median over the runs, in ``unit``."""
    unit: str = "s"
    target: float | None = None
    """The issue's target in ``unit`` (lower is better); None when there is none."""
    runs: int = 1
    baseline: str = ""
    """What the ratio compares against (measured in the same run), e.g. 'numpy FPS loop'."""
    ratio: float | None = None
    """median / baseline median."""
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool | None:
        return None if self.target is None else self.median <= self.target

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["ok"] = self.ok
        return d


def median_time(fn: Callable[[], Any], runs: int = 5, warmup: int = 1) -> float:
    """Median wall time (s) of ``fn()`` over ``runs`` calls after ``warmup`` unmeasured ones."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def percentile(values: list[float], p: float) -> float:
    """The ``p``-th percentile (0-100) of ``values`` by linear interpolation."""
    v = sorted(values)
    k = (len(v) - 1) * p / 100
    lo, hi = int(k), min(int(k) + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)
