"""Spatial helpers for raw scans, numpy only: up axis, trunk base, even thinning, point spacing.

Split out of ``pointio`` (which re-exports them) so that file stays about reading and writing.
"""

from __future__ import annotations

import numpy as np

from .repeats import distinct_rows


def guess_up_axis(points: np.ndarray) -> tuple[str, float]:
    """Guess whether a tree stands along +Z or +Y; returns ('z' | 'y', confidence in [0.5, 1)).

    For each candidate axis, an upright score: log(elongation) - 0.75 log(trunk / width), where
    elongation is the robust extent along the axis (0.5-99.5 percentile) over the crown width across it
    (2 x the 95th percentile distance from the median), and trunk is the same width measured in the lowest
    10% of the extent. Ground under the axis (``ground_band``) is left out first and adds
    ``GROUND_BONUS``: a scan's ground disc as wide as the tree is tall hid its trunk and turned it on its
    side. An axis whose footprint is a line
    (its thin side under ``SLAB_RATIO`` of both its long side and the extent along the axis: a flat cloud
    stood on its edge, not a row of trees) loses 4 log(ratio / SLAB_RATIO). Trees are taller than wide,
    narrow at the foot and round in plan. X is never a candidate; a tie goes to Z. The confidence is a
    logistic of the score difference. See docs/scan-input.md for limits.
    """
    pts = np.asarray(points, dtype=np.float64)
    pts = pts[distinct_rows(pts)[0]]  # a pile of copies (no-return rows at one spot) is one point
    if len(pts) > 50_000:
        pts = pts[np.random.default_rng(0).choice(len(pts), 50_000, replace=False)]
    s_z, s_y = _upright_score(pts, 2), _upright_score(pts, 1)
    confidence = float(1.0 / (1.0 + np.exp(-2.0 * min(abs(s_z - s_y), 20.0))))
    return ("y" if s_y > s_z else "z"), confidence


SLAB_RATIO = 0.1
"""Footprint thinner than this fraction of its length and of the height: the cloud lies on its side."""
GROUND_CELLS = 50
"""``ground_band`` grids the plane across the axis in cells of 1/this of the cloud's largest extent."""
GROUND_SHARE = 0.5
"""Ground under an axis: at least this share of the occupied columns have their lowest point on a smooth,
gentle surface (``ground_band``)."""
GROUND_TOL = 0.01
"""A column's lowest point is on the surface when within this fraction of the extent along the axis of
the median of its 3 x 3 columns' lowest points."""
GROUND_TILT = 0.5
"""... and the surface there rises at most this much per unit across (27 degrees)."""
GROUND_BAND = 0.03
"""Left out as ground: the points less than this fraction of the extent above their column's ground, and
up to the first slice that is trunk-narrow again (grass)."""
GROUND_BONUS = 1.0
"""Added to the score of an axis with ground under it and more than ground above: ground lies under a
tree, so seen from the side (the other axis) it is a wall, which still reads as a tall, narrow-footed
shape."""


def _upright_score(pts: np.ndarray, axis: int) -> float:
    ground = ground_band(pts, axis)
    bonus = 0.0
    if ground is not None and ground.mean() < 0.95:  # a ground patch alone stays whole
        pts, bonus = pts[~ground], GROUND_BONUS
    h = pts[:, axis]
    across = np.delete(pts, axis, axis=1)
    eps = 1e-9 * float(np.ptp(pts, axis=0).max())
    lo, hi = np.percentile(h, [0.5, 99.5])
    width = 2.0 * _spread(across)
    trunk = 2.0 * _spread(across[h <= lo + 0.1 * (hi - lo)])
    elongation = max(hi - lo, eps) / max(width, eps)
    narrow = min(max(trunk / max(width, eps), 0.01), 100.0)
    return float(np.log(elongation) - 0.75 * np.log(narrow) + 4.0 * np.log(_footprint(across, hi - lo, eps)) + bonus)


def _footprint(across: np.ndarray, height: float, eps: float) -> float:
    """min(1, (thin side of the footprint / the smaller of its long side and ``height``) / SLAB_RATIO):
    below 1 for a slab standing on its edge (a ground disc read with the wrong up axis), whose footprint
    is a line and which is as tall as it is long; a crown's is round, and a row of trees, whose footprint
    is a line too, is much lower than long and as deep as it is tall."""
    ext = np.percentile(across, 99.5, axis=0) - np.percentile(across, 0.5, axis=0)
    return min(1.0, max(float(ext.min()), eps) / max(min(float(ext.max()), height), eps) / SLAB_RATIO)


def ground_band(pts: np.ndarray, axis: int) -> np.ndarray | None:
    """(N,) bool: the ground (and grass) of ``pts`` (N, 3) when ``axis`` has ground under it, else None.

    The lowest point of each column (``GROUND_CELLS``) is ground where it lies on a smooth, gentle
    surface: within ``GROUND_TOL`` of the median of its 3 x 3 columns' lowest points, which rises at most
    ``GROUND_TILT`` there. Flat, sloped, domed, hollow or rough ground passes; a crown's underside or
    near side does not (its edges are steep), nor a tree's front seen from the side. When at least
    ``GROUND_SHARE`` of the columns are ground, the band left out is the points less than
    ``GROUND_BAND`` of the extent above their column's lowest point (the surface's, for a column whose
    lowest point is far above it), and up to the first 1 % slice above that is half as wide as the band
    (a trunk rising through grass). Session 18: one plane found by RANSAC missed ground that curved by 4 %
    of the height, and the tree was turned on its side.
    """
    h = pts[:, axis]
    lo, hi = np.percentile(h, [0.5, 99.5])
    height = float(hi - lo)
    across = np.delete(pts, axis, axis=1)
    cell = float(np.ptp(pts, axis=0).max()) / GROUND_CELLS
    if height <= 0 or cell <= 0:
        return None
    ij = np.floor((across - across.min(axis=0)) / cell).astype(np.int64)
    shape = tuple(ij.max(axis=0) + 1)
    if min(shape) < 3:
        return None
    column = np.ravel_multi_index(ij.T, shape)
    low = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(low, column, h)
    low = np.where(np.isfinite(low), low, np.nan).reshape(shape)
    surface = _median3(low)
    slope = np.hypot(*np.gradient(surface, cell))
    occupied = np.isfinite(low)
    with np.errstate(invalid="ignore"):
        on = occupied & (np.abs(low - surface) < GROUND_TOL * height) & (slope < GROUND_TILT)
        if occupied.sum() < 20 or on.sum() < GROUND_SHARE * occupied.sum():
            return None
        base = np.where(np.isfinite(surface) & (np.abs(low - surface) >= 0.1 * height), surface, low)
    up = h - base.ravel()[column]
    return up < _grass_top(up, across, height)


def _median3(grid: np.ndarray) -> np.ndarray:
    """The median of each cell's 3 x 3 neighbourhood of ``grid`` (NaN: empty), NaN where all are empty."""
    import warnings

    pad = np.pad(grid, 1, constant_values=np.nan)
    rows, cols = grid.shape
    stack = np.stack([pad[i:i + rows, j:j + cols] for i in range(3) for j in range(3)], axis=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods
        return np.nanmedian(stack, axis=2)


def _grass_top(up: np.ndarray, across: np.ndarray, height: float) -> float:
    """How far above its ground the band of ``ground_band`` reaches: ``GROUND_BAND`` of ``height``, or the
    first 1 % slice from there to 20 % that is half as wide as the band (the trunk above the grass)."""
    band = GROUND_BAND * height
    wide = _spread(across[np.abs(up) < band])
    step = 0.01 * height
    for k in range(3, 20):
        sl = (up >= k * step) & (up < (k + 1) * step)
        if sl.sum() >= 5 and _spread(across[sl]) < 0.5 * wide:
            return k * step  # k >= 3: never under the band
    return band


def _spread(xy: np.ndarray, q: float = 95.0) -> float:
    """The ``q``-th percentile distance of 2D points (M, 2) from their median."""
    return (
        float(np.percentile(np.linalg.norm(xy - np.median(xy, axis=0), axis=1), q))
        if len(xy)
        else 0.0
    )


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
