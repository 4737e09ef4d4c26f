"""Spatial helpers for raw scans, numpy only: trunk base, column bounds, even thinning, point spacing.

Split out of ``pointio`` (which re-exports them) so that file stays about reading and writing; the way
up is in ``pointio_up``.
"""

from __future__ import annotations

import numpy as np


def trunk_base(points: np.ndarray, slab_fraction: float = 0.02, min_points: int = 20) -> np.ndarray:
    """The trunk base (3,): median X and Y of the lowest slab of points, and the lowest Z.

    The slab holds the points within ``slab_fraction`` of the height above the lowest point, or the
    ``min_points`` lowest points when it holds fewer (a stray low point cannot move the base much).
    """
    pts = np.asarray(points, dtype=np.float64)
    z = pts[:, 2]
    slab = pts[z <= z.min() + slab_fraction * np.ptp(z)]
    if len(slab) < min_points:
        slab = pts[np.argsort(z, kind="stable")[: min(min_points, len(pts))]]
    x, y = np.median(slab[:, :2], axis=0)
    return np.array([x, y, z.min()])


def column_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis minimum and maximum (3,) of ``points`` (N, 3): ``points.min(axis=0)`` but one column
    at a time, about ten times faster on a large C-ordered array."""
    lo = np.array([points[:, a].min() for a in range(points.shape[1])])
    hi = np.array([points[:, a].max() for a in range(points.shape[1])])
    return lo, hi


def voxel_keys(points: np.ndarray, size: float) -> np.ndarray:
    """An int64 key (N,) per point of ``points`` (N, 3) for cubic voxels of side ``size`` from their
    lowest corner: equal keys, one voxel."""
    ijk = np.floor((points - points.min(axis=0)) / size).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    return ijk @ np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)


def even_sample_indices(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices (n,) int64, ascending, of ``n`` points spread evenly over ``points`` (N, 3).

    Voxel grid then random fill: the voxel size is found by bisection so that about ``n`` voxels are
    occupied (on a random subset of 200,000 points for larger clouds); points are ranked at random within
    their voxel, and the ``n`` points of lowest rank are kept (ties at random). Every voxel so keeps one
    point before any voxel keeps two, and dense parts of a scan are thinned more than sparse ones. Same
    ``rng`` state, same result.
    """
    pts = np.asarray(points, dtype=np.float64)
    count = len(pts)
    if n >= count:
        return np.arange(count)
    probe = (
        pts
        if count <= max(200_000, 4 * n)
        else pts[rng.choice(count, max(200_000, 4 * n), replace=False)]
    )
    keys = voxel_keys(pts, _voxel_size_for(probe, n))
    order = _shuffled_argsort(keys, rng)
    sorted_keys = keys[order]
    first = np.concatenate([[True], sorted_keys[1:] != sorted_keys[:-1]])
    rank = np.zeros(count, dtype=np.int64)
    rank[order] = np.arange(count) - np.maximum.accumulate(np.where(first, np.arange(count), 0))
    return np.sort(_shuffled_argsort(rank, rng)[:n])


def _shuffled_argsort(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices sorting ``values``, equal values in random order."""
    perm = rng.permutation(len(values))
    return perm[np.argsort(values[perm], kind="stable")]


def _voxel_size_for(pts: np.ndarray, n: int, steps: int = 10) -> float:
    """A voxel size at which about ``n`` (at most ``n`` where possible) voxels of ``pts`` are occupied."""
    extent = float(np.ptp(pts, axis=0).max())
    lo, hi = np.log2(extent) - 20.0, np.log2(extent) + 0.01
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if np.unique(voxel_keys(pts, 2.0**mid)).size > n:
            lo = mid
        else:
            hi = mid
    return float(2.0**hi)


def median_spacing(points: np.ndarray, rng: np.random.Generator, samples: int = 2000) -> float:
    """Median nearest-neighbour distance (metres) over up to ``samples`` random points of ``points``.

    Exact for the sampled points: neighbours are searched in the 27 cells around each sampled point of
    a voxel grid of cell size h (``_first_cell_size``: from the 1st-99th percentile extent of the sample,
    so a stray point far away does not put every point in every cell); a point whose nearest neighbour
    is not within h is searched again with 2h (or at once with the cell size that must hold the nearest
    point found so far). One pass with integer arithmetic over all points picks the points in the cells
    of the next ``POOL_LEVELS`` doublings around the sampled points; sorting and distances involve only
    those, so the work grows with the sample, not with N log N.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 2:
        return 0.0
    query = rng.choice(len(pts), min(samples, len(pts)), replace=False)
    lo, hi = column_bounds(pts)
    grid = _Grid(pts, _first_cell_size(pts[query], len(pts), float((hi - lo).max())), lo, hi)
    h = grid.h
    dist = np.full(len(query), np.inf)
    level = np.zeros(len(query), dtype=np.int64)
    pending, pool, pool_level = np.arange(len(query)), None, -1
    while pending.size:
        k = int(level[pending].min())
        at = pending[level[pending] == k]
        if k > pool_level:
            pool_level = k + POOL_LEVELS
            pool = grid.near(query[pending], pool_level, None)
        found = grid.nearest(query[at], k, pool)
        done = found <= h * 2.0**k
        dist[at[done]] = found[done]
        miss, far = at[~done], found[~done]
        level[miss] = k + 1
        # a point found beyond the cells' reach bounds the distance: jump to a cell size that holds it
        seen = np.isfinite(far)
        level[miss[seen]] = np.maximum(k + 1, np.ceil(np.log2(far[seen] / h)))
        pending = np.setdiff1d(pending, at[done])
    return float(np.median(dist))


def _first_cell_size(sample: np.ndarray, count: int, extent: float) -> float:
    """Cell size h of ``median_spacing``'s first search: the robust extent of ``sample`` (M, 3) (largest
    1st-99th percentile range over the axes) over sqrt(``count``), so one stray point far away cannot
    make every cell hold every point; at least ``extent`` (the full extent) / 2**``MAX_CELL_BITS``, so
    cell indices and keys stay within int32 / int64. Any h gives the same (exact) result."""
    lo, hi = np.percentile(sample, [1.0, 99.0], axis=0)
    robust = float((hi - lo).max())
    return max(robust / np.sqrt(count), extent / 2.0**MAX_CELL_BITS, 1e-12)


MAX_CELL_BITS = 20
"""Largest cell index of ``median_spacing``'s grid along an axis, as a power of two: with 3 padding cells
per axis, a key (``_Grid.keys``) stays below 2**61."""
POOL_LEVELS = 2
"""Cell doublings one pass over all points serves (``median_spacing``): its pool holds the 27 cells
of size 4 h around each sampled point, so the searches at h and 2h need no other pass."""
CANDIDATE_BUDGET = 4_000_000
"""Largest number of (query, candidate) distances ``_Grid.nearest`` holds at once."""
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
"""Fibonacci hashing multiplier (2**64 / golden ratio) for ``_CellSet``."""
_OFFSETS = np.stack(np.meshgrid(*[[-1, 0, 1]] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
"""(27, 3) the cell and its 26 neighbours."""


class _Grid:
    """Points in nested voxel grids: cells of size h * 2**level, level 0, 1, ..., from one integer
    cell index per point (the cell at level k is the index shifted right by k)."""

    ROWS = 1 << 20
    """Points per block of a pass over all points (a few tens of MB of temporaries)."""

    def __init__(self, pts: np.ndarray, h: float, lo: np.ndarray, hi: np.ndarray) -> None:
        self.pts, self.h = pts, h
        self.cells = np.zeros(pts.shape, dtype=np.int32)
        for s in range(0, len(pts), self.ROWS):
            self.cells[s : s + self.ROWS] = np.floor((pts[s : s + self.ROWS] - lo) / h)
        self.top = np.floor((hi - lo) / h).astype(np.int64)
        """(3,) the largest cell index along each axis (that of ``hi``)."""

    def keys(self, index: np.ndarray | slice, level: int) -> tuple[np.ndarray, np.ndarray]:
        """int64 key of the level's cell of each ``pts[index]`` (padded by one cell on each side, so
        neighbour keys never wrap) and the key strides (3,)."""
        dims = (self.top >> level) + 3
        strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
        c = self.cells[index] >> level
        return ((c[:, 0] + 1) * strides[0] + (c[:, 1] + 1) * strides[1]) + (c[:, 2] + 1), strides

    def near(self, query: np.ndarray, level: int, pool: np.ndarray | None) -> np.ndarray:
        """Indices (ascending) of the ``pool`` points (all, in blocks, for None) in the level's 27
        cells around each ``pts[query]``."""
        keys, strides = self.keys(query, level)
        wanted = _CellSet(np.unique(keys[:, None] + (_OFFSETS @ strides)[None]))
        if pool is not None:
            return pool[wanted.find(self.keys(pool, level)[0])]
        blocks = range(0, len(self.pts), self.ROWS)
        return np.concatenate([s + wanted.find(self.keys(slice(s, s + self.ROWS), level)[0]) for s in blocks])

    def nearest(self, query: np.ndarray, level: int, pool: np.ndarray | None) -> np.ndarray:
        """Distance (Q,) from each ``pts[query]`` to its nearest other point among the ``pool``
        points in the level's 27 cells around it (inf when they hold none)."""
        near = self.near(query, level, pool)
        keys, strides = self.keys(near, level)
        order = np.argsort(keys, kind="stable")
        near, keys = near[order], keys[order]
        wanted = self.keys(query, level)[0][:, None] + (_OFFSETS @ strides)[None]
        left = np.searchsorted(keys, wanted, "left")
        lengths = np.searchsorted(keys, wanted, "right") - left
        taken = np.cumsum(lengths.sum(axis=1))  # candidates of queries 0..i together
        out = np.full(len(query), np.inf)
        s = 0
        while s < len(query):  # in slices of at most CANDIDATE_BUDGET candidates (at least one query)
            before = int(taken[s - 1]) if s else 0
            e = max(s + 1, int(np.searchsorted(taken, before + CANDIDATE_BUDGET, "right")))
            out[s:e] = self._nearest_in(query[s:e], near, left[s:e], lengths[s:e])
            s = e
        return out

    def _nearest_in(self, q: np.ndarray, near: np.ndarray, left: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Distance (Q,) from each ``pts[q]`` to its nearest other point among
        ``near[left:left + lengths]`` of its 27 cells (``left``, ``lengths``: (Q, 27))."""
        left, lengths = left.reshape(-1), lengths.reshape(-1)
        owner = np.repeat(np.arange(left.size), lengths)
        within = np.arange(owner.size) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        cand = near[left[owner] + within]
        row = owner // len(_OFFSETS)
        d = np.linalg.norm(self.pts[cand] - self.pts[q[row]], axis=1)
        d[cand == q[row]] = np.inf
        best = np.full(len(q), np.inf)
        np.minimum.at(best, row, d)
        return best


class _CellSet:
    """A few cell keys (M,) to find among many (N,), M << N, in one pass over the many: a bit table
    of about 64 M entries, indexed by a hash of the key, lets through every wanted key and about 1 in
    64 others; only those are then looked up exactly."""

    def __init__(self, wanted: np.ndarray) -> None:
        self.wanted = wanted
        """(M,) int64, sorted, unique."""
        self.bits = int(min(max(np.ceil(np.log2(64 * len(wanted) + 1)), 16), 26))
        self.table = np.zeros(1 << self.bits, dtype=bool)
        self.table[_hash(wanted, self.bits)] = True

    def find(self, keys: np.ndarray) -> np.ndarray:
        """Indices (ascending) of the ``keys`` (N,) int64 that are wanted."""
        maybe = np.flatnonzero(self.table[_hash(keys, self.bits)])
        pos = np.minimum(np.searchsorted(self.wanted, keys[maybe]), len(self.wanted) - 1)
        return maybe[self.wanted[pos] == keys[maybe]]


def _hash(keys: np.ndarray, bits: int) -> np.ndarray:
    """A ``bits``-bit hash (uint64, same shape) of non-negative int64 ``keys`` (Fibonacci hashing)."""
    out = keys.astype(np.uint64)
    out *= _GOLDEN  # wraps modulo 2**64, as intended
    out >>= np.uint64(64 - bits)
    return out
