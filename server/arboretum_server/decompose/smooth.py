"""Branch smoothing after Algorithm 1 (ours, not in VRTree: its Fig. 4 shows smooth branches).

Branches are shortest paths through scan points, resampled every ``step`` and centred in the cloud, so
they zig-zag by about the point spacing. We smooth every branch polyline with a few iterations of
umbrella (Laplacian) smoothing, v_k += w ((v_{k-1} + v_{k+1}) / 2 - v_k), with the branch's first
vertex (its connection point on the parent) and its tip fixed, and each vertex's total displacement
clipped to ``limit`` (about the branch radius / point spacing at the 0.8 m scale) so the curve stays in
the data. Vertex counts do not change, so ``parent_vertex`` indices stay valid; parents are smoothed
before children and every child's first vertex is set to its parent's smoothed vertex, so the
topology stays connected exactly. Eq. (1) (the joint) is applied before and kept.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from .merge import BranchSet, add_branch

ITERATIONS = 12
"""Smoothing iterations (each moves a vertex ``WEIGHT`` of the way to its neighbours' midpoint)."""
WEIGHT = 0.5
"""Umbrella-operator step w."""
LIMIT = 0.012
"""Largest displacement of a vertex from its unsmoothed position (0.8 m scale)."""
LOCAL_SPACINGS = 2.0
"""With a point cloud, a vertex moves at most this many local point spacings (median distance of its 8
nearest points); that limit is clipped to [``LIMIT_MIN``, ``LIMIT``]."""
LIMIT_MIN = 0.004
"""Smallest per-vertex displacement limit (0.8 m scale)."""
INFLATE = 0.0
"""Taubin's mu: every second iteration steps by -``INFLATE`` (0: plain Laplacian smoothing)."""


def vertex_limits(segments: list[np.ndarray], tree: cKDTree | None) -> float | np.ndarray:
    """Displacement limits: ``LOCAL_SPACINGS`` local point spacings per vertex of ``segments`` (one array
    over all their vertices) when a k-d ``tree`` of the cloud is given, else ``LIMIT``."""
    if tree is None or not segments:
        return LIMIT
    d = tree.query(np.concatenate(segments), k=8)[0]
    median = 0.5 * (d[:, 3] + d[:, 4])  # np.median of the 8 sorted distances, bit for bit, without its sort
    return np.clip(LOCAL_SPACINGS * median, LIMIT_MIN, LIMIT)


def smooth_polylines(segments: list[np.ndarray], limit: float | np.ndarray = LIMIT, iterations: int = ITERATIONS,
                     weight: float = WEIGHT) -> list[np.ndarray]:
    """All ``segments`` (L_i, 3) smoothed at once, first and last vertices fixed; each vertex moves at most
    ``limit`` (a scalar or one value per vertex of the concatenated segments)."""
    if not segments:
        return []
    lens = np.array([len(s) for s in segments])
    flat = np.concatenate(segments).astype(np.float64)
    orig = flat.copy()
    starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
    inner = np.ones(len(flat), bool)
    inner[starts] = False
    inner[starts + lens - 1] = False
    idx = np.flatnonzero(inner)
    lim = np.broadcast_to(np.asarray(limit, dtype=np.float64), (len(flat),))[idx]
    if len(idx) == 0:
        return [s.copy() for s in segments]
    steps = np.array([-INFLATE if (it % 2 and INFLATE) else weight for it in range(iterations)], np.float64)
    _smooth_kernel(flat, orig, idx, np.ascontiguousarray(lim), steps)
    return np.split(flat, np.cumsum(lens)[:-1])


@njit(cache=True)
def _smooth_kernel(flat, orig, idx, lim, steps):  # pragma: no cover - numba
    """``smooth_polylines``' iterations in place on ``flat``, the numpy steps they replace (session 23: 224
    -> 15 us on a 40-vertex branch; a refinement smooths a few short ones many times), the same operations in the same
    order: every inner vertex moves towards its neighbours' old midpoint, then back within its limit."""
    moved = np.zeros((len(idx), 3))
    for w in steps:
        for a in range(len(idx)):
            i = idx[a]
            for k in range(3):
                moved[a, k] = flat[i, k] + w * (0.5 * (flat[i - 1, k] + flat[i + 1, k]) - flat[i, k])
        for a in range(len(idx)):
            i = idx[a]
            d0, d1, d2 = moved[a, 0] - orig[i, 0], moved[a, 1] - orig[i, 1], moved[a, 2] - orig[i, 2]
            n = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            r = lim[a] / (n if not n < 1e-300 else 1e-300)  # np.maximum: a NaN stays NaN
            scale = r if not r > 1.0 else 1.0  # np.minimum
            flat[i, 0], flat[i, 1], flat[i, 2] = orig[i, 0] + d0 * scale, orig[i, 1] + d1 * scale, orig[i, 2] + d2 * scale


def depths(parents: list[int]) -> np.ndarray:
    """(B,) depth of each branch (0 for roots; parents must come before children)."""
    d = np.zeros(len(parents), int)
    for b, p in enumerate(parents):
        d[b] = d[p] + 1 if p >= 0 else 0
    return d


def smooth_branchset(kept: BranchSet, tree: cKDTree | None = None, iterations: int = ITERATIONS) -> BranchSet:
    """A new BranchSet with every segment smoothed, parents first (level by level, vectorised per level),
    each child's first vertex exactly its parent's smoothed ``parent_vertex``; ``full``/``owner`` rebuilt and
    the unsmoothed full paths kept in ``raw_full`` for Algorithm 1 step 2.
    ``tree`` (a k-d tree of the cloud) ties the displacement limits to the local point spacing."""
    segs = [s.copy() for s in kept.segments]
    dep = depths(kept.parents)
    for level in range(int(dep.max()) + 1 if len(dep) else 0):
        members = np.flatnonzero(dep == level)
        for b in members:
            p = kept.parents[b]
            if p >= 0:
                segs[b][0] = segs[p][kept.parent_vertex[b]]
        level_segs = [segs[b] for b in members]
        for b, s in zip(members, smooth_polylines(level_segs, vertex_limits(level_segs, tree), iterations)):
            segs[b] = s
    out = BranchSet()
    for s, p, pv in zip(segs, kept.parents, kept.parent_vertex):
        add_branch(out, s, p, pv)
    out.raw_full = [kept.reference(b) for b in range(len(kept.full))]
    return out


def warm() -> None:
    """Run ``_smooth_kernel`` once on a three-vertex polyline (see ``tetloops.warm``)."""
    smooth_polylines([np.array([[0.0, 0, 0], [0, 0, 1], [0, 0, 2]])], np.full(3, 0.01))
