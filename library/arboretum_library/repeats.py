"""Exact duplicate rows of a point cloud: which rows to keep, and what was repeated.

Merged scans repeat points, and scanners write rows without a return as (0, 0, 0). Coincident points
break what follows them: Delaunay drops them (alpha shapes fall back to convex hulls), a random sample of
a cloud holding a million copies of one point is mostly that point, and a kNN query over coincident
points takes quadratic time. ``distinct_rows`` finds the first row holding each point with one sort of
a 64-bit hash of the rows (exact: rows are compared after the hash), so a cloud without repeats costs one
hash and one sort. numpy only: the decomposition's preprocessing and the up-axis guess of ``pointio``
use it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

_MIX = np.array([0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB], np.uint64)
"""Odd multipliers of ``_row_hash`` (splitmix64's)."""



class Repeats(NamedTuple):
    """Exact duplicates merged by ``distinct_rows`` (scan frame and units)."""

    rows: int
    """Rows looked at (the finite ones)."""
    merged: int
    """Rows dropped as copies of an earlier row."""
    repeated: int
    """Distinct points given more than once."""
    most: int
    """Rows holding the most repeated point (1: nothing repeats)."""
    fewest: int
    """Rows holding the least repeated of the repeated points (1: nothing repeats)."""
    at: tuple[float, float, float] | None
    """The most repeated point; None when nothing repeats."""
    apart: float | None = None
    """Distance from ``at`` to the nearest other point; None when nothing repeats."""
    left_out: bool = False
    """``at`` stood ``PILE_APART`` apart and was left out (``far_pile``)."""

    def as_stats(self) -> dict:
        """The figures as plain numbers (JSON, msgpack) for ``Decomposition.stats['repeated']``."""
        return self._asdict() | {"at": None if self.at is None else [float(v) for v in self.at]}


def _row_hash(pts: np.ndarray) -> np.ndarray:
    """(N,) uint64 hash of the rows of ``pts`` (N, 3) float64: equal for equal coordinates (-0.0 as 0.0)."""
    bits = np.ascontiguousarray(pts + 0.0).view(np.uint64)
    h = bits[:, 0] * _MIX[0]
    for j in (1, 2):
        h ^= h >> np.uint64(31)
        h += bits[:, j]
        h *= _MIX[j]
    return h ^ (h >> np.uint64(29))


def _groups(pts: np.ndarray, h: np.ndarray, hs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order, start) of ``pts`` (N, 3) with row hashes ``h`` (N,) (``hs``: sorted): ``order`` (N,) puts equal rows
    together, earliest row first; ``start`` (N,) bool marks where each run of equal rows begins in it.

    Runs of equal hashes are checked against their first row; on a hash collision the rows are sorted
    by their coordinates instead (exact, but several times slower)."""
    order = np.argsort(h, kind="stable")
    start = np.r_[True, hs[1:] != hs[:-1]]
    later = np.flatnonzero(~start)  # sorted positions after the first of their run
    head = order[np.flatnonzero(start)[np.cumsum(start)[later] - 1]]
    if (pts[head] == pts[order[later]]).all():
        return order, start
    order = np.lexsort(pts.T[::-1])
    s = pts[order]
    return order, np.r_[True, (s[1:] != s[:-1]).any(axis=1)]


def distinct_rows(pts: np.ndarray) -> tuple[np.ndarray, Repeats]:
    """(N,) bool, True at the first row of ``pts`` (N, 3) finite float64 holding each point, and the
    ``Repeats`` of the others.

    One sort of a 64-bit hash of the rows (``_row_hash``): 0.1 s for a million points; a cloud without
    repeats is answered by it alone."""
    none = Repeats(len(pts), 0, 0, 1, 1, None)
    h = _row_hash(pts)
    hs = np.sort(h)
    if len(hs) < 2 or (hs[1:] != hs[:-1]).all():
        return np.ones(len(pts), bool), none
    order, start = _groups(pts, h, hs)
    heads = np.flatnonzero(start)
    first = np.zeros(len(pts), bool)
    first[order[heads]] = True
    n = np.diff(np.r_[heads, len(pts)])
    if n.max() == 1:  # a hash collision only
        return first, none
    big = int(np.argmax(n))
    x, y, z = (float(v) for v in pts[order[heads[big]]] + 0.0)
    return first, Repeats(len(pts), len(pts) - len(heads), int((n > 1).sum()), int(n[big]),
                          int(n[n > 1].min()), (x, y, z))
