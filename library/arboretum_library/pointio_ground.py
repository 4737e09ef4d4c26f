"""The ground under a cloud along an axis, numpy only: ``ground_band`` (the ground and grass a tree stands
on, left out before ``pointio_up`` scores the axis) and ``_ground`` (the same, None for a ground patch alone).

Here: the grid of columns across the axis and the smooth, gentle surface of their lowest points
(multipath under it left out), hummocky ground on a coarser grid (``_rough_ground``, ``_relief``), the
upper level of a terrace's edge (``_steps``) and of a flight of steps (``_flight``, ``_treads``), grass
(``_grass_top``), and two measures ``pointio_up`` and ``pointio_wall`` share (``_spread``,
``_largest_extent``). Split out of ``pointio_up`` in session 24 (helper-173).
"""

from __future__ import annotations

import numpy as np

from .pointio_spatial import column_bounds

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


GROUND_PASSES, GROUND_DEEP = 2, 0.03
"""Multipath (returns under the ground, a few per cent of a TLS scan's): the points more than ``GROUND_TOL``
under the surface are left out and the surface found again, this many times, when they are at most this
share of the points (more is a crown's or rough ground's own relief: the first surface is kept)."""


GROUND_BAND = 0.03
"""Left out as ground: the points less than this fraction of the extent above their column's ground, and
up to the first slice that is trunk-narrow again (grass)."""


def ground_band(pts: np.ndarray, axis: int) -> np.ndarray | None:
    """(N,) bool: the ground (and grass) of ``pts`` (N, 3) when ``axis`` has ground under it, else None.

    The lowest point of each column (``GROUND_CELLS``) is ground where it lies on a smooth, gentle
    surface: within ``GROUND_TOL`` of the median of its 3 x 3 columns' lowest points, which rises at most
    ``GROUND_TILT`` there. Flat, sloped, domed, hollow or rough ground passes; a crown's underside or
    near side does not (its edges are steep), nor a tree's front seen from the side. When at least
    ``GROUND_SHARE`` of the columns are ground, the band left out is the points less than
    ``GROUND_BAND`` of the extent above their column's lowest point (the surface's, for a column whose
    lowest point is far above it), and up to the first 1 % slice above that is half as wide as the band
    (a trunk rising through grass). In a column across a terrace's edge or a flight of steps, the upper
    level's band is left out too (``_steps``, ``_upper_level``; sessions 22-23). Session 18: one plane
    found by RANSAC missed ground that curved by 4 % of the height, and the tree was turned on its side.
    Session 20: multipath under the ground became the lowest point of too many columns and hid it (a
    tree turned Y up at 0.91); it is left out first (``GROUND_PASSES``) and lies in the band. Session 22:
    hummocky ground (bumps of 3 % of the height, 0.1-0.2 heights apart) is neither, and the tree was
    turned on its side (Y at 0.95): it is found on a coarser grid (``_rough_ground``) and its relief is in
    the band.
    """
    return _band(pts, axis)[0]


def _ground(pts: np.ndarray, axis: int) -> np.ndarray | None:
    """``ground_band`` of ``pts`` along +``axis``, None when it is everything (a ground patch alone)."""
    ground = ground_band(pts, axis)
    return ground if ground is not None and ground.mean() < 0.95 else None


def _band(pts: np.ndarray, axis: int) -> tuple[np.ndarray | None, int]:
    """``ground_band`` and the number of columns whose upper level it left out (``_steps``)."""
    h = pts[:, axis]
    lo, hi = np.percentile(h, [0.5, 99.5])
    height = float(hi - lo)
    across = np.delete(pts, axis, axis=1)
    cell = _largest_extent(pts) / GROUND_CELLS
    if height <= 0 or cell <= 0:
        return None, 0
    column, shape = _columns(across, cell)
    if min(shape) < 3:
        return None, 0
    found, low, surface = _ground_surface(h, column, shape, cell, height)
    rough = not found and _rough_ground(low, cell, height)
    if not (found or rough):
        return None, 0
    base = _base(low, surface, height)
    up = h - base.ravel()[column]
    top = _grass_top(up, across, height)
    band = up < top + (_relief(up, column, low.size, height) if rough else 0.0)
    stepped = np.zeros(low.size, dtype=bool)
    rises = [(rise, False) for rise in _steps(low, surface, base, height)]  # the upper level across an edge
    for rise, flight in rises + [(rise, True) for rise in _flight(low, surface, base, height)]:
        upper = _upper_level(up, column, rise.ravel(), height, flight)
        band |= upper
        stepped[column[upper]] = True
    return band, int(stepped.sum())


ROUGH_CELLS, ROUGH_TOL, ROUGH_SHARE, ROUGH_FILL = 2, 0.05, 0.8, 0.6
"""Hummocky ground (``_rough_ground``): on columns this many times as wide as ``ground_band``'s, at least
this share of the occupied columns have their lowest point within this fraction of the extent of their
3 x 3 median, on a gentle surface, and the occupied columns fill at least this share of the grid (ground
is a patch). Bumps of 3-6 % of a tree's height 0.1-0.5 heights apart: 0.83-0.99 of the columns, filling
0.82; trees without ground seen along Z or Y either way, and the bumpy disc seen edge on: at most 0.49;
a tree with a wall beside it and no ground: 0.53-0.83, filling 0.24-0.69 (without the fill, 25 more of
helper-140's 1,728 wall files read wrong at a share of 0.6, and a pine beside a wall 2 heights long read
Y at 0.93 at 0.8)."""


ROUGH_RISE, ROUGH_REACH = 0.35, 75.0
"""The band over hummocky ground (``_relief``): a column's points up to its highest when that is at most
this fraction of the extent over its lowest (ground alone), else up to this percentile of those
highest over all the columns (ground under the crown: the trunk's foot is left out with it)."""


def _rough_ground(low: np.ndarray, cell: float, height: float) -> bool:
    """Whether hummocky ground lies under a cloud whose columns' lowest points are ``low`` (``ground_band``'s
    grid of ``cell``-wide columns): the test of ``_on_surface`` on ``ROUGH_CELLS`` times wider columns,
    within ``ROUGH_TOL``, for ``ROUGH_SHARE``, on a grid ``ROUGH_FILL`` full. Bumps of 3 % of the height,
    0.2 heights apart, leave 0.45 of the lowest points within ``GROUND_TOL`` of their 3 x 3 median on the
    finer grid, where a column spans half a bump; a wider column's lowest point is its hollow, and the
    hollows lie on a smooth surface. The wider columns' lowest points are the least of ``low``'s, not the
    points' again: it runs for every end of an axis without ground, up to 4 times a guess."""
    k = ROUGH_CELLS
    pad = np.pad(low, ((0, -low.shape[0] % k), (0, -low.shape[1] % k)), constant_values=np.nan)
    wide = pad[::k, ::k]
    for i, j in ((i, j) for i in range(k) for j in range(k) if i or j):
        wide = np.fmin(wide, pad[i::k, j::k])
    occupied = np.isfinite(wide)
    if min(wide.shape) < 3 or occupied.sum() < max(20, ROUGH_FILL * occupied.size):
        return False  # a line or a scatter of columns, not a patch of ground
    surface = _median3(wide)
    slope = np.hypot(*np.gradient(surface, k * cell))
    with np.errstate(invalid="ignore"):
        on = occupied & (np.abs(wide - surface) < ROUGH_TOL * height) & (slope < GROUND_TILT)
    return bool(on.sum() >= ROUGH_SHARE * occupied.sum())


def _relief(up: np.ndarray, column: np.ndarray, count: int, height: float) -> np.ndarray:
    """(N,) how far above the band each point's column of hummocky ground reaches (``up``: the points'
    heights over their column's ground; ``count`` columns): the column's highest point when at most
    ``ROUGH_RISE`` of ``height`` over it, else the ``ROUGH_REACH`` percentile of those. A band of 3 % left
    the bumps' tops in the foot slice, which was then as wide as the ground (3.0-3.5 times the height)."""
    high = np.full(count, -np.inf)
    np.maximum.at(high, column, up)
    cap = ROUGH_RISE * height
    under_crown = min(float(np.percentile(high[np.isfinite(high)], ROUGH_REACH)), cap)
    return np.where(high <= cap, high + 1e-9 * height, under_crown)[column]


def _base(low: np.ndarray, surface: np.ndarray, height: float) -> np.ndarray:
    """Each column's ground (``ground_band``'s grid): its lowest point, or the surface where that is more
    than a tenth of ``height`` off it (a crown's underside over the ground)."""
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(surface) & ~(np.abs(low - surface) < 0.1 * height), surface, low)


def _columns(across: np.ndarray, cell: float) -> tuple[np.ndarray, tuple[int, int]]:
    """The column (flat index) of each point of ``across`` (N, 2) on a grid of ``cell``-wide columns from
    its lowest corner, and the grid's shape."""
    ij = np.floor((across - column_bounds(across)[0]) / cell).astype(np.int64)
    shape = tuple(column_bounds(ij)[1] + 1)
    return np.ravel_multi_index(ij.T, shape), shape


def _ground_surface(h: np.ndarray, column: np.ndarray, shape: tuple, cell: float, height: float) -> tuple:
    """Whether ``ground_band`` finds ground (``_on_surface``), and the lowest point of each column and the
    surface it is measured from (the median of those lowest points): found on all the points or, once
    what lies more than ``GROUND_TOL`` under the surface is left out (multipath, ``GROUND_PASSES``), on
    the rest; the lowest points then exclude it, so the band starts above it. (Until session 21 the
    surface was the pass before's; the bands were the same in 399 of 400 multipath clouds.)"""
    low, surface = _low_surface(h, column, shape, None)
    first = (_on_surface(low, surface, cell, height), low, surface)
    keep, found = np.ones(len(h), dtype=bool), first[0]
    for k in range(GROUND_PASSES + 1):
        if k:
            low, surface = _low_surface(h, column, shape, keep)
            found = found or _on_surface(low, surface, cell, height)
        with np.errstate(invalid="ignore"):
            keep &= ~(h < surface.ravel()[column] - GROUND_TOL * height)
        if keep.mean() < 1.0 - GROUND_DEEP:  # a crown's or rough ground's own relief, not multipath
            return first
    low, surface = _low_surface(h, column, shape, keep)
    return found, low, surface


def _on_surface(low: np.ndarray, surface: np.ndarray, cell: float, height: float) -> bool:
    """Whether at least ``GROUND_SHARE`` of the occupied columns (20 at least) have their lowest point
    on a smooth, gentle surface (``ground_band``)."""
    slope = np.hypot(*np.gradient(surface, cell))
    occupied = np.isfinite(low)
    on = occupied & (np.abs(low - surface) < GROUND_TOL * height) & (slope < GROUND_TILT)
    return bool(occupied.sum() >= 20 and on.sum() >= GROUND_SHARE * occupied.sum())


def _low_surface(h: np.ndarray, column: np.ndarray, shape: tuple, keep: np.ndarray | None) -> tuple:
    """The lowest ``keep`` point (None: all) of each column (NaN: none) and the median of its 3 x 3 columns'."""
    low = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(low, column if keep is None else column[keep], h if keep is None else h[keep])
    low = np.where(np.isfinite(low), low, np.nan).reshape(shape)
    return low, _median3(low)


def _median3(grid: np.ndarray) -> np.ndarray:
    """The median of each cell's 3 x 3 neighbourhood of ``grid`` (NaN: empty), NaN where all are empty.
    Sorted by hand: ``np.nanmedian`` over masked arrays took 0.6 ms a call, called 4-12 times a guess."""
    pad = np.pad(grid, 1, constant_values=np.nan)
    rows, cols = grid.shape
    stack = np.sort(np.stack([pad[i:i + rows, j:j + cols] for i in range(3) for j in range(3)], axis=2), axis=2)
    n = np.isfinite(stack).sum(axis=2, keepdims=True)  # NaN sorts last
    half = np.take_along_axis(stack, np.maximum(n - 1, 0) // 2, 2) + np.take_along_axis(stack, n // 2 - (n == 0), 2)
    return np.where(n > 0, 0.5 * half, np.nan)[:, :, 0]


GROUND_STEP, STEP_COLUMNS, STEP_ON = 0.15, 20, 0.95
"""A terrace's edge (``_steps``): a neighbouring column's ground more than ``GROUND_BAND`` and at most this
fraction of the extent above a column's own, level with the neighbour opposite (a step of 10 % of a
tree's height is 0.106 of scan 06's extent; a flight's neighbour opposite is lower by at most as much);
terraces (and flights) have at least this many such columns (an edge runs across the ground) and at
least this share of the occupied columns on the surface (real ground under a tree: 0.999-1.0; a tree's
or a wall's side taken for ground: 0.66-0.90, whose few rises moved wall-sweep confidences by up to
0.09; a trunk's column on a 15-45 % slope: 1-4 columns)."""


def _steps(low: np.ndarray, surface: np.ndarray, base: np.ndarray, height: float) -> tuple:
    """The terrace edges of ``ground_band``'s grid: for each column, the rises from its ``base`` to the
    lowest and the highest ground (a lowest point within ``GROUND_TOL`` of its 3 x 3 median) of its 8
    neighbours lying more than ``GROUND_BAND`` and at most ``GROUND_STEP`` of ``height`` above it while the
    neighbour opposite is level with it (0: none); () when the grid has no terraces (``STEP_COLUMNS``,
    ``STEP_ON``). A column across a terrace's edge holds both levels; the band from its lowest point left
    the upper level in (a step of 6 % of the height against a band of 3 %), which widened the trunk's
    slice from 0.37 m to 14-15 m and left Z unsure (0.52-0.61, session 21). Only the upper level is left
    out, not the height between: a trunk standing on the edge keeps its foot (leaving out the column up
    to the upper band took it, and Z fell from 0.98 to 0.58). A flight of steps is ``_flight``'s."""
    lowest, highest = np.full(base.shape, np.inf), np.zeros(base.shape)
    for d, across in _rises(low, surface, base, height):
        with np.errstate(invalid="ignore"):  # NaN: no rise, or an empty column
            step = np.isfinite(d) & (np.abs(across) < GROUND_TOL * height)
        lowest = np.where(step, np.minimum(lowest, d), lowest)
        highest = np.where(step, np.maximum(highest, d), highest)
    if (highest > 0).sum() < STEP_COLUMNS:
        return ()
    return np.where(np.isfinite(lowest), lowest, 0.0), highest


def _flight(low: np.ndarray, surface: np.ndarray, base: np.ndarray, height: float) -> tuple:
    """The rises of a flight of steps on ``ground_band``'s grid: for each column, the lowest rise of
    ``_steps``' kind whose neighbour opposite is lower instead of level, by at most ``GROUND_STEP`` (0:
    none), as a 1-tuple; () when fewer than ``STEP_COLUMNS`` columns have one. Where the treads are a
    column deep, each column holds two and the neighbour opposite is a step lower: ``_steps`` found no
    edge, the upper treads were scored as the foot (its slice 2.9 heights wide) and Z read 0.54-0.72
    (helper-154's stairs of 5 %: 31 of 40 files wrong until session 23, 2 now, the guiding default
    preset's Y files, unsure on flat ground too). A smooth slope steeper than a band a column rises the
    same way, so ``_upper_level`` takes a flight's tread only over a gap (taken like a terrace's, a
    crown's flank seen from below lost its upper levels, and 7 of helper-136's upside-down files were
    kept as written). Its neighbour opposite may lie off the surface (``_rises``' ``rim``); the treads a
    column holds under its neighbour's level are ``_treads``'."""
    lowest = np.full(base.shape, np.inf)
    for d, across in _rises(low, surface, base, height, rim=True):
        with np.errstate(invalid="ignore"):
            down = np.isfinite(d) & (across <= -GROUND_TOL * height) & (across >= -GROUND_STEP * height)
        lowest = np.where(down, np.minimum(lowest, d), lowest)
    found = np.isfinite(lowest)
    return (np.where(found, lowest, 0.0),) if found.sum() >= STEP_COLUMNS else ()


def _rises(low: np.ndarray, surface: np.ndarray, base: np.ndarray, height: float, rim: bool = False) -> list:
    """For each of a column's 8 neighbours on ``ground_band``'s grid, (its ground over the column's
    ``base`` where it rises more than ``GROUND_BAND`` and at most ``GROUND_STEP`` of ``height``, else NaN;
    the neighbour opposite's ground over it: with ``rim``, its lowest point even off the surface); [] unless
    ``STEP_ON`` of the occupied columns have their lowest point within ``GROUND_TOL`` of their 3 x 3
    median (that point is a column's ground here). At the ground's rim a column has 6 neighbours or
    fewer, and the median of a flight's lowest points there is off them: ``_flight`` asks ``rim`` (a
    walnut at the top of a flight going down, the ground 3 heights out, kept 28 rim points of its ground
    out of the band, enough to widen its foot slice)."""
    with np.errstate(invalid="ignore"):
        level = np.where(np.abs(low - surface) < GROUND_TOL * height, low, np.nan)
    if np.isfinite(level).sum() < STEP_ON * np.isfinite(low).sum():
        return []
    pad = np.pad(level, 1, constant_values=np.nan)
    opposite = np.pad(low, 1, constant_values=np.nan) if rim else pad
    rows, cols = base.shape
    out = []
    with np.errstate(invalid="ignore"):  # NaN: an empty column
        for i, j in ((i, j) for i in range(3) for j in range(3) if (i, j) != (1, 1)):
            d = pad[i:i + rows, j:j + cols] - base
            d = np.where((d > GROUND_BAND * height) & (d <= GROUND_STEP * height), d, np.nan)
            out.append((d, opposite[2 - i:2 - i + rows, 2 - j:2 - j + cols] - base))
    return out


def _upper_level(up: np.ndarray, column: np.ndarray, rise: np.ndarray, height: float,
                 flight: bool = False) -> np.ndarray:
    """(N,) bool: the points of a column across a terrace's edge (``rise``: per column, 0 for none; ``up``:
    each point's height over its column's ground) within ``GROUND_BAND`` over the upper level, in columns
    whose next band up holds under a tenth as many points: nothing stands on the level there. A trunk on
    the edge does, and keeps its foot (taken, scan 06's band held 458 of its points instead of 159, and
    the guiding default tree's trunk slice moved up into its crown: Z at 0.70 became Y at 0.81). A
    ``flight``'s upper tread is taken only where the column holds under a tenth as many points between
    half a band and the tread: a tread over a tread, not a smooth slope."""
    r = rise[column]
    band = GROUND_BAND * height
    level = (r > 0) & (up >= r - GROUND_TOL * height) & (up < r + band)
    above = (r > 0) & (up >= r + band) & (up < r + 2.0 * band)
    count = len(rise)
    free = 10 * np.bincount(column[above], minlength=count) < np.bincount(column[level], minlength=count)
    if flight:  # a tread over a tread, nothing between: a smooth steep slope (a crown's side) fills it
        between = (r > 0) & (up >= 0.5 * band) & (up < r - GROUND_TOL * height)
        free &= 10 * np.bincount(column[between], minlength=count) < np.bincount(column[level], minlength=count)
        return (level & free[column]) | _treads(up, column, rise, height)
    return level & free[column]


TREAD_FILL = 0.5
"""A column of a flight holds treads of its own under its neighbour's level (``_treads``) when its points
there fill at most this share of the ``GROUND_TOL``-thin slices between (a tread fills one or two; a
crown's flank or a trunk fills them all)."""


TREAD_HELD = 3
"""... and it holds at least this many points from half a ``GROUND_BAND`` up through the level's band (5
until session 25: with the ground 3 heights out, 40,000 points, a column holds about 10, and a sparse
column's middle tread and the level over it held 4; left out of the band, they widened the trunk's slice
of the harmonic apple and cherry at the top of a flight of 8 % steps going down)."""


def _treads(up: np.ndarray, column: np.ndarray, rise: np.ndarray, height: float) -> np.ndarray:
    """(N,) bool: the treads a ``_flight`` column holds between its ground and its neighbour's level
    (``rise``), left out as ground: its points from half a ``GROUND_BAND`` up to that level fill at most
    ``TREAD_FILL`` of the ``GROUND_TOL``-thin slices there (``TREAD_HELD`` points at least), and nothing
    stands on them (the band over the level's band holds under a tenth as many points); the level's band
    goes with them. Where the ground
    reaches 3 heights out, a column is 0.12 heights wide and holds two or three treads 6 % deep:
    ``_upper_level`` took only the neighbour's level, the treads under it stayed out of the band and
    widened the foot slice (scan 06 at the top of a flight going down: Z -0.13 against Y 0.45 written Z
    up; its upside-down files, turned the right way up since session 23, were read on their side)."""
    r = rise[column]
    band, tol, count = GROUND_BAND * height, GROUND_TOL * height, len(rise)
    own = (r > 0) & (up >= 0.5 * band) & (up < r - tol)
    if not own.any():
        return own
    level = (r > 0) & (up >= r - tol) & (up < r + band)
    over = (r > 0) & (up >= r + band) & (up < r + 2.0 * band)
    slices = np.floor(up[own] / tol).astype(np.int64)
    span = int(slices.max()) + 1
    keys, hits = np.unique(column[own] * span + slices, return_counts=True)
    filled = np.bincount(keys[hits >= 2] // span, minlength=count)
    room = np.maximum((rise - tol - 0.5 * band) / tol, 1.0)  # slices from half a band to the level
    held = np.bincount(column[own | level], minlength=count)
    free = 10 * np.bincount(column[over], minlength=count) < held  # nothing stands on the treads
    ok = (filled <= TREAD_FILL * room) & free & (held >= TREAD_HELD)
    return (own | level) & ok[column]


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


def _largest_extent(pts: np.ndarray) -> float:
    """The largest extent of ``pts`` (N, 3) along an axis: ``np.ptp(pts, axis=0).max()``, faster."""
    lo, hi = column_bounds(pts)
    return float((hi - lo).max())
