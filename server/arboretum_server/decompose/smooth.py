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
from scipy.spatial import cKDTree

from arboretum_server.jitcache import njit

from .memo import ArrayMemo
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


GRID_CELLS = 2_000_000
"""Most cells of the dense grid ``spacing_grid`` lays over a cloud (16 MB of offsets); past that the
k-d tree answers ``vertex_limits`` alone."""
GRID_SIDE = 1.5
"""``spacing_grid``'s cell side, in median 5th-neighbour distances of the cloud."""
GRID_SHELLS = 3
"""Rings of cells ``_spacing_kernel`` searches round a vertex before it leaves the vertex to the k-d tree."""
_GRIDS = ArrayMemo()
"""``spacing_grid`` per k-d tree, by its data array while that lives (a refinement queries the same
cloud's tree some 20-60 times)."""


def vertex_limits(segments: list[np.ndarray], tree: cKDTree | None) -> float | np.ndarray:
    """Displacement limits: ``LOCAL_SPACINGS`` local point spacings per vertex of ``segments`` (one array
    over all their vertices) when a k-d ``tree`` of the cloud is given, else ``LIMIT``."""
    if tree is None or not segments:
        return LIMIT
    d = fifth_nearest(np.concatenate(segments), tree)
    median = 0.5 * (d[:, 0] + d[:, 1])  # np.median of the 8 sorted distances, bit for bit, without its sort
    return np.clip(LOCAL_SPACINGS * median, LIMIT_MIN, LIMIT)


def fifth_nearest(q: np.ndarray, tree: cKDTree) -> np.ndarray:
    """(M, 2): the distances from each of ``q`` (M, 3) to its 4th and 5th nearest points of ``tree``'s cloud,
    bit for bit ``tree.query(q, k=8)[0][:, 3:5]``: from ``spacing_grid``'s compiled search where it is
    sure of them, else from the tree (session 26: the tree's k = 8 query cost 2.5 us a vertex, a third of
    a refinement's smoothing)."""
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3)
    grid = spacing_grid(tree)
    if grid is None or not len(q):
        return tree.query(q, k=8)[0][:, 3:5]
    origin, cell, dims, start, sorted_pts = grid
    out = np.zeros((len(q), 2))
    ok = np.zeros(len(q), np.bool_)
    _spacing_kernel(q, origin, cell, dims, start, sorted_pts, GRID_SHELLS, out, ok)
    if not ok.all():
        out[~ok] = tree.query(q[~ok], k=8)[0][:, 3:5]
    return out


def spacing_grid(tree: cKDTree) -> tuple | None:
    """The cloud of ``tree`` sorted into a dense grid of cubic cells (origin, cell side, dims, offsets of
    each cell's points, the sorted points), the side the median 5th-neighbour distance of 64 of its points;
    None for fewer than 5 points, a degenerate side or more than ``GRID_CELLS`` cells. Kept per tree."""
    data = tree.data
    hit = _GRIDS.get(data)
    if hit is None:
        hit = _GRIDS.put(data, (_build_grid(np.asarray(data), tree),))
    return hit[0]


def _build_grid(pts: np.ndarray, tree: cKDTree) -> tuple | None:
    if len(pts) < 5 or not np.isfinite(pts).all():
        return None
    cell = GRID_SIDE * float(np.median(tree.query(pts[:: max(1, len(pts) // 64)], k=5)[0][:, 4]))
    if not cell > 0:
        return None
    origin = pts.min(axis=0)
    dims = np.floor(np.ptp(pts, axis=0) / cell).astype(np.int64) + 1
    if float(np.prod(dims.astype(np.float64))) > GRID_CELLS:
        return None
    idx = np.minimum(np.floor((pts - origin) / cell).astype(np.int64), dims - 1)
    lin = (idx[:, 0] * dims[1] + idx[:, 1]) * dims[2] + idx[:, 2]
    order = np.argsort(lin, kind="stable")
    start = np.r_[0, np.cumsum(np.bincount(lin, minlength=int(np.prod(dims))))].astype(np.int64)
    return origin, cell, dims, start, np.ascontiguousarray(pts[order])


@njit(cache=True)
def _spacing_kernel(q, origin, cell, dims, start, pts, shells, out, ok):  # pragma: no cover - numba
    """``fifth_nearest`` by the grid: the five least squared distances ((dx^2 + dy^2) + dz^2, as cKDTree
    sums three coordinates) over rings of cells round each vertex's cell, ring by ring, until the fifth is
    below the distance every unvisited cell keeps from the vertex (ring * side + the vertex's margin in its
    own cell, less a relative 1e-9 for the cells' rounding); their square roots (cKDTree's distances) of
    the 4th and 5th into ``out``, ``ok`` set. A vertex not settled within ``shells`` rings is left."""
    best = np.zeros(5)
    c = np.zeros(3, np.int64)
    for p in range(q.shape[0]):
        best[:] = np.inf
        if not (np.isfinite(q[p, 0]) and np.isfinite(q[p, 1]) and np.isfinite(q[p, 2])):
            continue
        margin = np.inf
        for a in range(3):
            f = (q[p, a] - origin[a]) / cell
            c[a] = int(np.floor(f))
            lo = q[p, a] - (origin[a] + c[a] * cell)
            hi = (origin[a] + (c[a] + 1) * cell) - q[p, a]
            margin = min(margin, max(0.0, min(lo, hi)))
        for s in range(shells + 1):
            for ix in range(c[0] - s, c[0] + s + 1):
                if ix < 0 or ix >= dims[0]:
                    continue
                for iy in range(c[1] - s, c[1] + s + 1):
                    if iy < 0 or iy >= dims[1]:
                        continue
                    for iz in range(c[2] - s, c[2] + s + 1):
                        if iz < 0 or iz >= dims[2]:
                            continue
                        if max(abs(ix - c[0]), abs(iy - c[1]), abs(iz - c[2])) != s:
                            continue
                        lin = (ix * dims[1] + iy) * dims[2] + iz
                        for t in range(start[lin], start[lin + 1]):
                            dx, dy, dz = q[p, 0] - pts[t, 0], q[p, 1] - pts[t, 1], q[p, 2] - pts[t, 2]
                            d = dx * dx + dy * dy + dz * dz
                            if d < best[4]:
                                u = 4
                                while u > 0 and best[u - 1] > d:
                                    best[u] = best[u - 1]
                                    u -= 1
                                best[u] = d
            if np.sqrt(best[4]) < (s * cell + margin) * (1.0 - 1e-9):
                out[p, 0], out[p, 1] = np.sqrt(best[3]), np.sqrt(best[4])
                ok[p] = True
                break


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
    return [flat] if len(segments) == 1 else np.split(flat, np.cumsum(lens)[:-1])  # one: no np.split (20 us)


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
    vertex_limits([np.zeros((2, 3))], cKDTree(np.arange(30.0).reshape(10, 3) / 30.0))
