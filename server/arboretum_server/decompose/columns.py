"""Trunk-like columns away from the root: a second tree standing higher than the first (ours).

``trunkbase.find_root`` refuses separate trunks in the lowest 3 % of the height. A second tree whose
foot stands higher (up a slope with no ground scanned, on a bank) never enters that band and would be
decomposed as part of the first. Here every foot (the lowest point of an xy cell, lower than its
neighbours', in the lowest ``FOOT_TOP`` of the height) more than ``SEPARATE`` of the height from the
root is followed upwards: a column whose every slab holds most of what a slab of the root's own
trunk column holds (``FULL``, and at least ``MIN_SLAB`` points), and whose points lie within its
radius (``NARROW``), is reported. A drooping branch or a crown bent down to the ground can look the
same, so the decomposition goes on and the command prints a note; it does not refuse.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

FOOT_CELL = 0.02
"""Width of the xy cells whose lowest points are the candidate feet (fraction of the height)."""
FOOT_TOP = 0.2
"""Feet are searched below this fraction of the height above the root's foot."""
SEPARATE = 0.1
"""A foot at least this fraction of the height from the root in plan view is another trunk's."""
SPAN = 0.1
"""Height of the column followed above a foot (fraction of the height), in ``SLABS`` slabs."""
SLABS = 5
RECENTRE = 2
"""Times the first slab of a column is recentred on its points before it counts."""
FULL = 0.6
"""Every slab of a trunk column holds at least this share of the root column's median slab (the
probe's second trunks: 0.79 or more; drooping branch ends and crowns 0.31-0.56)."""
NARROW = 0.7
"""At least this share of the points within twice the column's radius lie within its radius."""
MIN_SLAB = 3
"""Fewest points in any slab of a trunk column (a root column with empty slabs makes ``FULL`` vacuous)."""


def column(tree, pts: np.ndarray, up: np.ndarray, xy: np.ndarray, foot: float, rho: float,
            h: float) -> tuple[np.ndarray, np.ndarray]:
    """Points per slab (SLABS,) within ``rho`` of a column rising from height ``foot`` at ``xy`` (its
    centre follows the points slab by slab), and those between ``rho`` and 2 ``rho`` (SLABS,). The
    first slab is recentred ``RECENTRE`` times on the mean of its points within 2 ``rho`` before it
    counts: a foot is a point on the bark, not on the axis."""
    core, ring = np.zeros(SLABS, np.int64), np.zeros(SLABS, np.int64)
    centre = np.asarray(xy, np.float64)
    for k in range(SLABS):
        lo = foot + k * SPAN * h / SLABS
        for again in range(RECENTRE, -1, -1) if k == 0 else (0,):
            idx = np.asarray(tree.query_ball_point(centre, 2 * rho), np.int64)
            idx = idx[(up[idx] >= lo) & (up[idx] < lo + SPAN * h / SLABS)]
            if again and len(idx):
                centre = pts[idx, :2].mean(axis=0)
        d = np.linalg.norm(pts[idx, :2] - centre, axis=1)
        core[k], ring[k] = int((d < rho).sum()), int((d >= rho).sum())
        if core[k] >= 3:
            centre = np.median(pts[idx[d < rho], :2], axis=0)
    return core, ring


def _feet(pts: np.ndarray, up: np.ndarray, h: float) -> np.ndarray:
    """Indices of the lowest point of each ``FOOT_CELL`` xy cell that lies below ``FOOT_TOP`` of the
    height ``h`` (``up`` (N,): heights above the root) and no higher than the lowest points of the 8
    cells around it. Only occupied cells are kept (a stray point far away costs no grid); the cells
    widen so that no axis holds more than 2 ** 20 of them."""
    low = np.flatnonzero(up < FOOT_TOP * h)
    if len(low) == 0:
        return low
    cell = max(FOOT_CELL * h, float(np.ptp(pts[low, :2], axis=0).max()) / 2 ** 20, 1e-300)
    key = np.floor((pts[low, :2] - pts[low, :2].min(axis=0)) / cell).astype(np.int64)
    ny = int(key[:, 1].max()) + 3  # occupied cells only: a stray point far away costs no grid
    cells, inv = np.unique((key[:, 0] + 1) * ny + key[:, 1] + 1, return_inverse=True)
    cmin = np.full(len(cells), np.inf)
    np.minimum.at(cmin, inv, up[low])
    around = cmin.copy()
    for off in (dx * ny + dy for dx in (-1, 0, 1) for dy in (-1, 0, 1)):
        j = np.searchsorted(cells, cells + off).clip(max=len(cells) - 1)
        hit = cells[j] == cells + off
        around[hit] = np.minimum(around[hit], cmin[j[hit]])
    return low[(up[low] == cmin[inv]) & (cmin == around)[inv]]


class Column(NamedTuple):
    """A trunk-like column away from the root, in the units and frame of the points searched."""

    foot: tuple[float, float, float]
    """Its lowest point (x, y, z)."""
    distance: float
    """Plan-view distance of the foot from the root."""
    rise: float
    """Height of the foot above the root's (both measured from the ground plane when there is one)."""


def trunk_columns(pts: np.ndarray, root: np.ndarray, up: np.ndarray) -> list[Column]:
    """Each trunk-like column of ``pts`` (N, 3) away from ``root`` (3,), nearest first. ``up`` (N,):
    each point's height above the ground plane, or its z when there is none."""
    from scipy.spatial import cKDTree

    h = float(up.max() - up.min())
    if h <= 0:
        return []
    plan = np.linalg.norm(pts[:, :2] - root[:2], axis=1)
    near = (up < up.min() + 0.03 * h) & (plan < SEPARATE * h)
    if near.sum() < 5:
        return []
    rho = max(1.5 * float(np.percentile(plan[near], 90)), 0.01 * h)
    rise = up - float(up[near].min())  # height above the root
    keep = np.flatnonzero(rise < (FOOT_TOP + SPAN) * h)
    tree = cKDTree(pts[keep, :2])
    core0, _ = column(tree, pts[keep], rise[keep], root[:2], 0.0, rho, h)
    if core0.sum() == 0:
        return []
    found: list[np.ndarray] = []
    out = []
    for i in _feet(pts, rise, h):
        if plan[i] < SEPARATE * h or any(np.linalg.norm(pts[i, :2] - f) < 2 * rho for f in found):
            continue
        core, ring = column(tree, pts[keep], rise[keep], pts[i, :2], float(rise[i]), rho, h)
        if (core.min() >= max(FULL * np.median(core0), MIN_SLAB)
                and core.sum() >= NARROW * (core.sum() + ring.sum())):
            found.append(pts[i, :2])
            out.append(Column(tuple(float(v) for v in pts[i]), float(plan[i]), float(rise[i])))
    return sorted(out, key=lambda c: c.distance)
