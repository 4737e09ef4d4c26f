"""The way up of a raw scan, numpy only: ``guess_up`` (+Z, +Y, or either upside down), the turns to Z up,
and ``ground_band`` (the ground under an axis).

Split out of ``pointio_spatial`` (session 19), which keeps the trunk base, thinning and spacing;
``pointio`` re-exports both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .pointio_spatial import column_bounds
from .repeats import distinct_rows

UP_DIRECTIONS = ("z", "y", "z-down", "y-down")
"""The ways up ``guess_up`` tells apart: +Z, +Y, -Z (a file upside down), -Y."""


@dataclass(frozen=True)
class UpGuess:
    """What ``guess_up`` found: the way up of a cloud, and how sure it is of the axis."""

    direction: str
    """One of ``UP_DIRECTIONS``: the axis that scored higher, and its way up."""
    confidence: float
    """In [0.5, 1): how sure the axis (Z or Y) is; a logistic of the score difference."""
    z_direction: str
    """'z' or 'z-down': the way up along Z, for a file kept on Z when the confidence is too low for Y."""
    z_ground: bool = False
    """Whether ground lies under the cloud along +Z as given (``_ground``): ``trunk_on_top`` reuses it."""


def guess_up(points: np.ndarray) -> UpGuess:
    """Guess the way up of a tree: +Z, +Y, or either upside down (``UP_DIRECTIONS``).

    For each axis the way up is found first (``_upside_down``: ground at the top end with a trunk on it,
    or reaching well beyond the plant),
    then the axis is scored that way up with ``_upright_score``: log(elongation) - 0.75 log(trunk /
    width), where elongation is the robust extent along the axis (0.5-99.5 percentile) over the crown
    width across it (2 x the 95th percentile distance from the median), and trunk is the same width
    measured in the lowest 10% of the extent. Ground under the axis (``ground_band``) is left out first
    and adds ``GROUND_BONUS``: a scan's ground disc as wide as the tree is tall hid its trunk and turned
    it on its side. An axis whose footprint is a line (its thin side under ``SLAB_RATIO`` of both its
    long side and the extent along the axis: a flat cloud stood on its edge, not a row of trees) loses
    4 log(ratio / SLAB_RATIO). A wall or a fence beside the tree (``_wall``) standing along an axis with
    no ground at either end is left out of that axis's score, and the other axis, when ground was found
    along it, loses its bonus: the wall's length read as a tree's height turned it on its side, and a
    wall facing the other axis is a smooth, gentle surface that ``ground_band`` takes for ground (session
    21: 292 of helper-140's 1,728 wall files wrong, 27 now). Trees are taller than wide, narrow at the
    foot and round in plan. X is never a candidate; a tie goes to Z. See docs/scan-input.md for limits.
    """
    pts = _sample(points)
    z_way, s_z, z_ground, z_any, z_bonus = _way_up(pts, 2)
    y_way, s_y, _, y_any, y_bonus = _way_up(pts, 1)
    if not (z_any and y_any):  # ground along one axis at most: it may be a wall beside the tree
        wall = np.zeros(len(pts), dtype=bool)
        for axis, any_ground in ((2, z_any), (1, y_any)):
            if not any_ground:
                wall |= _wall(pts, axis)
        if wall.any():  # scored without the wall; an axis whose "ground" it was loses the bonus
            s_z = s_z - z_bonus if z_any else _upright_score(pts[~wall], 2, None)
            s_y = s_y - y_bonus if y_any else _upright_score(pts[~wall], 1, None)
    else:  # ground along both: one may be the face of a wall standing on the other
        standing = _wall_on_ground(pts, ((2, z_way, z_bonus), (1, y_way, y_bonus)))
        if standing is not None:
            axis, score = standing
            s_z, s_y = (score, s_y - y_bonus) if axis == 2 else (s_z - z_bonus, score)
    confidence = float(1.0 / (1.0 + np.exp(-2.0 * min(abs(s_z - s_y), 20.0))))
    return UpGuess(y_way if s_y > s_z else z_way, confidence, z_way, z_ground)


WALL_GROUNDED = 0.9
"""A wall found along an axis with ground (``_wall_on_ground``) with at least this share of its points in
that axis's ground band is the ground seen edge on, not a wall (the pine scan's own ground: 1.0; walls
3 heights long standing on stairs: 0.44-0.72)."""


def _wall_on_ground(pts: np.ndarray, axes: tuple) -> tuple[int, float] | None:
    """(axis, score) of the one axis (``axes``: (axis, way up, ``GROUND_BONUS`` in its score), both with
    ground at some end) with ground under it along which a wall stands beside the tree (``_wall``, the
    cloud turned that way up; not ``WALL_GROUNDED`` in its ground band) whose other axis has no ground
    left without it (that ground was the wall's face), scored without the wall (its ground found
    again); None when there is none, or one along each (ground seen edge on may pass for a
    wall: which is which is not told). Stairs beside a wall 3 heights long facing Y: seen along Y the
    wall's face is ground, so the wall search did not run, and the wall kept in Z's score (its length
    the crown's width, its foot the trunk's) read the tree on its side (helper-154's 80 files: 70 wrong)."""
    found = []
    for k, (axis, way, bonus) in enumerate(axes):
        if not bonus:
            continue
        turned = _turned(pts, axis, way)
        wall = _wall(turned, axis)
        if not wall.any():
            continue
        ground = _ground(turned, axis)  # not None: the bonus is for it
        if ground is None or (wall & ground).sum() >= WALL_GROUNDED * wall.sum():
            continue
        other, other_way, _ = axes[1 - k]
        if _ground(_turned(pts, other, other_way)[~wall], other) is not None:
            continue  # the other axis's ground was not the wall's face
        rest = turned[~wall]
        found.append((axis, _upright_score(rest, axis, _ground(rest, axis))))
    return found[0] if len(found) == 1 else None


def _turned(pts: np.ndarray, axis: int, way: str) -> np.ndarray:
    """``pts`` with ``axis`` negated when ``way`` is upside down ('z-down', 'y-down'), else itself."""
    if not way.endswith("-down"):
        return pts
    flipped = pts.copy()
    flipped[:, axis] *= -1.0
    return flipped


def _sample(points: np.ndarray) -> np.ndarray:
    """``points`` as float64 without repeats (a pile of copies, no-return rows at one spot, is one point)
    and at most a fixed random 50,000 of them: what the way-up tests look at."""
    pts = np.asarray(points, dtype=np.float64)
    pts = pts[distinct_rows(pts)[0]]
    if len(pts) > 50_000:
        pts = pts[np.random.default_rng(0).choice(len(pts), 50_000, replace=False)]
    return pts


def guess_up_axis(points: np.ndarray) -> tuple[str, float]:
    """The axis of ``guess_up``: ('z' | 'y', confidence in [0.5, 1)), whichever way up it is."""
    guess = guess_up(points)
    return guess.direction[0], guess.confidence


_TO_ZUP = {
    "z": ((0, 1.0), (1, 1.0), (2, 1.0)),
    "y": ((0, 1.0), (2, -1.0), (1, 1.0)),
    "z-down": ((0, 1.0), (1, -1.0), (2, -1.0)),
    "y-down": ((0, 1.0), (2, 1.0), (1, -1.0)),
}
"""For each way up, each Z-up axis as (file axis, sign): rotations (right-handed both sides)."""


def turn_to_zup(points: np.ndarray, direction: str) -> np.ndarray:
    """``points`` (N, 3) of a file whose way up is ``direction`` (``UP_DIRECTIONS``), turned Z up:
    'y' (x, y, z) -> (x, -z, y) as ``geometry.yup_to_zup``; 'z-down' -> (x, -y, -z), half a turn about
    X; 'y-down' -> (x, z, -y). 'z' returns ``points`` itself."""
    if direction == "z":
        return points
    p = np.asarray(points)
    return np.stack([sign * p[:, col] for col, sign in _TO_ZUP[direction]], axis=1)


def turn_from_zup(points: np.ndarray, direction: str) -> np.ndarray:
    """The inverse of ``turn_to_zup``: Z-up ``points`` (N, 3) back in the frame of a file whose way up is
    ``direction``."""
    if direction == "z":
        return points
    p = np.asarray(points)
    out = np.zeros(p.shape, dtype=p.dtype)
    for k, (col, sign) in enumerate(_TO_ZUP[direction]):
        out[:, col] = sign * p[:, k]
    return out


def _way_up(pts: np.ndarray, axis: int) -> tuple[str, float, bool, bool, float]:
    """The way up along ``axis`` (2: 'z' or 'z-down', 1: 'y' or 'y-down'), its upright score, whether
    ground lies under ``pts`` along +``axis`` as given, whether ground lies at either end, and the
    ``GROUND_BONUS`` in the score (0 when the ground is not under the way up)."""
    flipped = pts.copy()
    flipped[:, axis] *= -1.0
    grounds = (_ground(pts, axis), _ground(flipped, axis))
    down = _upside_down(pts, flipped, axis, grounds)
    name = "zy"[2 - axis] + ("-down" if down else "")
    score = _upright_score(flipped if down else pts, axis, grounds[down])
    bonus = GROUND_BONUS if grounds[down] is not None else 0.0
    return name, score, grounds[0] is not None, any(g is not None for g in grounds), bonus


WALL_BAND, WALL_SHARE, WALL_THIN, WALL_LOW = 0.01, 0.05, 0.5, 0.5
"""A wall beside a tree with no ground (``_wall``): the points within this fraction of the largest extent
of a line in the footprint; its thin core (a quarter of that) holds at least this share of the points
and this share of the band's, 90 % of them in this lowest fraction of the extent along the axis. A wall
one tree height long, 0.3 % of it thick, holds 0.53-0.59 of its band in its core (0.6 until session 21
missed it); a slice of crown spread evenly across the band holds a quarter."""
WALL_TRIES, WALL_SAMPLE, WALL_KEEP = 100, 4000, 20
"""``_wall`` tries this many lines through two points of a fixed random sample of this many; a wall's
core holds, and leaves, at least this many points."""


def _wall(pts: np.ndarray, axis: int) -> np.ndarray:
    """(N,) bool: the points of a wall (or a fence) standing along ``axis`` beside the tree, all False
    when none. On ``WALL_SAMPLE`` points drawn at random (fixed; with repeats; all of a smaller cloud),
    the line in the footprint across ``axis`` holding the most of the lower half's points within a quarter
    of ``WALL_BAND`` (``WALL_TRIES`` lines through two of them) is a wall when that thin band holds
    ``WALL_SHARE`` of the points and ``WALL_THIN`` of those within ``WALL_BAND`` (a wall is thin; a slice
    of crown is not), and 90 % of them lie in the lowest ``WALL_LOW`` of the extent along ``axis`` (a wall
    is lower than the tree; a row's trunks are not). Its points there are the wall (a crown may reach over
    it). A wall has at least ``WALL_KEEP`` points in its core and leaves as many to score."""
    none = np.zeros(len(pts), dtype=bool)
    if len(pts) < WALL_KEEP:  # 3 points drawn 4,000 times made a "wall" of 2 and left 1 to score
        return none
    rng = np.random.default_rng(0)
    sub = pts if len(pts) <= WALL_SAMPLE else pts[rng.integers(0, len(pts), WALL_SAMPLE)]
    lo, hi = np.percentile(sub[:, axis], [0.5, 99.5])
    top = lo + WALL_LOW * (hi - lo)
    low = np.delete(sub[sub[:, axis] < top], axis, axis=1)
    if len(low) < WALL_KEEP or not hi > lo:
        return none
    a, b = low[rng.integers(0, len(low), WALL_TRIES)], low[rng.integers(0, len(low), WALL_TRIES)]
    d = b - a
    norm = np.hypot(d[:, 0], d[:, 1])
    if not (norm > 0).any():
        return none
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)[norm > 0] / norm[norm > 0, None]
    off = np.einsum("ij,ij->i", n, a[norm > 0])
    band = WALL_BAND * _largest_extent(pts)
    best = int(np.argmax((np.abs(low @ n.T - off) < 0.25 * band).sum(axis=0)))
    dist = np.abs(np.delete(sub, axis, axis=1) @ n[best] - off[best])
    thin = dist < 0.25 * band
    if thin.mean() < WALL_SHARE or thin.sum() < max(WALL_KEEP, WALL_THIN * (dist < band).sum()):
        return none
    if (sub[thin, axis] < top).mean() < 0.9:
        return none
    wall = (np.abs(np.delete(pts, axis, axis=1) @ n[best] - off[best]) < band) & (pts[:, axis] < top)
    return wall if (~wall).sum() >= WALL_KEEP else none


def _ground(pts: np.ndarray, axis: int) -> np.ndarray | None:
    """``ground_band`` of ``pts`` along +``axis``, None when it is everything (a ground patch alone)."""
    ground = ground_band(pts, axis)
    return ground if ground is not None and ground.mean() < 0.95 else None


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
GROUND_PASSES, GROUND_DEEP = 2, 0.03
"""Multipath (returns under the ground, a few per cent of a TLS scan's): the points more than ``GROUND_TOL``
under the surface are left out and the surface found again, this many times, when they are at most this
share of the points (more is a crown's or rough ground's own relief: the first surface is kept)."""
GROUND_BAND = 0.03
"""Left out as ground: the points less than this fraction of the extent above their column's ground, and
up to the first slice that is trunk-narrow again (grass)."""
GROUND_BONUS = 1.0
"""Added to the score of an axis with ground under it and more than ground above: ground lies under a
tree, so seen from the side (the other axis) it is a wall, which still reads as a tall, narrow-footed
shape."""


def _upright_score(pts: np.ndarray, axis: int, ground: np.ndarray | None) -> float:
    """The upright score of ``pts`` along +``axis`` (``guess_up``); ``ground`` (``_ground``) is left out."""
    bonus = 0.0
    if ground is not None:
        pts, bonus = pts[~ground], GROUND_BONUS
    h = pts[:, axis]
    across = np.delete(pts, axis, axis=1)
    eps = 1e-9 * _largest_extent(pts)
    lo, hi = np.percentile(h, [0.5, 99.5])
    width = 2.0 * _spread(across)
    trunk = 2.0 * _spread(across[h <= lo + 0.1 * (hi - lo)])
    elongation = max(hi - lo, eps) / max(width, eps)
    narrow = min(max(trunk / max(width, eps), 0.01), 100.0)
    return float(np.log(elongation) - 0.75 * np.log(narrow) + 4.0 * np.log(_footprint(across, hi - lo, eps)) + bonus)


def _upside_down(pts: np.ndarray, flipped: np.ndarray, axis: int, grounds: tuple) -> bool:
    """Whether the tree stands upside down along ``axis`` (``flipped``: ``pts`` with that axis negated;
    ``grounds``: their ``_ground``): ground lies at the top end and not at the bottom (``_ground_under``;
    a wall beside a tree is found from both ends), and a trunk stands on it: the narrowest
    ``_foot_widths`` slice next to it under ``TRUNK_NARROW`` (grass, slopes and occlusion allowed; a
    palm's or an umbrella pine's flat crown top read from above is a smooth, gentle surface too, with
    crown under it: ground that turns a file lies near one plane, ``_planar``, or on terraces,
    ``_terraced``). Where no trunk shows (a shrub, a tree with a pole, a skirt of branches), ground
    reaching ``GROUND_WIDE`` times farther out than the rest along both axes across does (a wall's face,
    long but lower than the tree, does not). Without ground the file is read as written: a trunk-like
    top is also a conifer's bare leader, a dead top or a pole beside the tree (helper-136: that rule
    turned 40 of 308 upright files without ground); ``trunk_on_top`` tells it for a note."""
    under = [_ground_under(p, axis, g) for p, g in zip((pts, flipped), grounds)]
    if not (under[1] < GROUND_UNDER <= under[0]):  # a wall found as ground from both ends: no way up
        return False
    rest = flipped[~grounds[1]]
    if len(rest) == 0 or not (_planar(flipped, axis, grounds[1]) or _terraced(flipped, axis)):  # a crown's dome
        return False
    if _foot_widths(rest, axis).min() < TRUNK_NARROW:
        return True
    across = np.delete(flipped, axis, axis=1)  # no trunk seen: ground reaching out beyond the rest both ways
    ext = [np.subtract(*np.percentile(a, [97.5, 2.5], axis=0)) for a in (across[grounds[1]], across[~grounds[1]])]
    return bool((ext[0] > GROUND_WIDE * ext[1]).all())


GROUND_PLANE, PLANE_SHARE = 0.08, 0.75
"""Ground that turns a file lies near one plane: ``PLANE_SHARE`` of its columns within this fraction of
the extent along the axis (``_planar``)."""


def _planar(pts: np.ndarray, axis: int, ground: np.ndarray) -> bool:
    """Whether the ground surface of ``pts`` (N, 3) (the middle ``ground`` point of each ``GROUND_CELLS``
    column: multipath lies under it) lies near one plane: ``PLANE_SHARE`` of it within ``GROUND_PLANE`` of
    the extent along ``axis`` of the plane fitted to its closest three quarters (thrice; in a sparse scan
    some columns' band points are the tree's). A leaf-off crown's top read from above is a smooth,
    gentle surface too, and the band over it swallows the crown, leaving the trunk to stand on it: the toy
    tree's leaf-off scans were turned upside down in 11 of 18 (up to 0.999 sure). Their domes (4 or 6
    limbs) measure 0.096-0.147 (three quarters of the columns); ground discs under 22 shapes, 2,000 or
    30,000 points, at most 0.009; a bowl 12 % of the tree's height deep, or a dome or valley 16 %, passes."""
    g = pts[ground]
    across = np.delete(g, axis, axis=1)
    column = _columns(across, _largest_extent(pts) / GROUND_CELLS)[0]
    order = np.lexsort((g[:, axis], column))
    starts = np.flatnonzero(np.r_[True, np.diff(column[order]) != 0])
    mid = order[(starts + np.r_[starts[1:], len(order)]) // 2]  # each column's middle point (multipath lies under it)
    design, height = np.c_[across[mid], np.ones(len(mid))], g[mid, axis]
    fit_to = np.ones(len(mid), dtype=bool)
    for _ in range(3):
        fit = np.linalg.lstsq(design[fit_to], height[fit_to], rcond=None)[0]
        off = np.abs(height - design @ fit)
        fit_to = off <= np.percentile(off, 75)
    return bool(np.percentile(off, 100 * PLANE_SHARE) <= GROUND_PLANE * float(np.ptp(pts[:, axis])))


def _terraced(pts: np.ndarray, axis: int) -> bool:
    """Whether the ground under ``pts`` (N, 3) along +``axis`` has terrace edges or a flight of steps:
    ``ground_band`` left out an upper level in ``STEP_COLUMNS`` columns or more (``_steps``, ``_flight``).
    Such ground is no plane but several levels (a flight of 8 steps of 5 % of the height joins two 0.4
    heights apart), and ``_planar`` kept its upside-down files as written. Only run for ground at the top
    end of an axis with a trunk on it."""
    return _band(pts, axis)[1] >= STEP_COLUMNS


def trunk_on_top(points: np.ndarray, guess: UpGuess | None = None) -> bool:
    """Whether a Z-up cloud (N, 3) may stand upside down though ``guess_up`` found no ground to say so:
    no ground under it, and its top end is a trunk (``_trunk``: even, narrow slices) over a lowest end
    more than ``FOOT_RATIO`` times wider. Also true of a conifer with a bare leader, a dead top or a pole
    taller than the tree, so it only asks for a note, never a turn. ``guess``: ``guess_up`` of ``points``
    as given (a file read Z up as written), whose search for ground under them is reused (3 ms)."""
    pts = _sample(points)
    if len(pts) < 20 or (guess.z_ground if guess is not None else _ground(pts, 2) is not None):
        return False
    flipped = pts * np.array([1.0, 1.0, -1.0])
    top = _foot_widths(flipped, 2)
    return _trunk(top) and bool(_foot_widths(pts, 2).min() > FOOT_RATIO * top.max())


def _ground_under(pts: np.ndarray, axis: int, ground: np.ndarray | None) -> float:
    """The share of the points off ``ground`` lying below its median height along ``axis`` (1.0 when
    no ground): near 0 for ground under a tree, near 1 for the ground seen from the crown's side (a
    ground disc wider than the crown is found from both ends)."""
    if ground is None or not ground.any():
        return 1.0
    h = pts[:, axis]
    return float(np.mean(h[~ground] < np.median(h[ground])))


def _foot_widths(pts: np.ndarray, axis: int) -> np.ndarray:
    """(FOOT_SLICES,) the width (2 x 95th percentile distance from the median) of each ``FOOT_STEP``
    slice from the lowest end along ``axis``, over the extent along it (0.5-99.5 percentile); inf when
    that extent is 0 (no foot, no trunk)."""
    h = pts[:, axis]
    across = np.delete(pts, axis, axis=1)
    lo, hi = np.percentile(h, [0.5, 99.5])
    height = float(hi - lo)
    if not height > 0:
        return np.full(FOOT_SLICES, np.inf)
    k = np.floor((h - lo) / height / FOOT_STEP)
    return np.array([2.0 * _spread(across[k == i]) / height for i in range(FOOT_SLICES)])


def _trunk(widths: np.ndarray) -> bool:
    """Foot slices (``_foot_widths``) that make a trunk: all under ``TRUNK_NARROW`` of the height, and
    even (the widest at most ``TRUNK_EVEN`` times the narrowest: a cone's tip widens 3 times)."""
    return bool(widths.max() < TRUNK_NARROW and widths.max() <= TRUNK_EVEN * widths.min())


GROUND_WIDE = 1.3
"""Ground at the top end with no trunk on it turns a cloud when it spans this many times more than the
rest along both axes across (2.5-97.5 percentiles): ground round a shrub, not a wall's face."""
GROUND_UNDER = 0.5
"""Ground lies under a tree when fewer than this share of the other points are below its median."""
FOOT_STEP, FOOT_SLICES = 0.03, 3
"""The foot of a cloud along an axis: this many slices of this fraction of the extent, from its end."""
TRUNK_NARROW, TRUNK_EVEN = 0.15, 2.5
"""A trunk (``_trunk``): foot slices under this fraction of the height, the widest at most this many
times the narrowest."""
FOOT_RATIO = 3.0
"""``trunk_on_top`` (a note, never a turn): the lowest end's narrowest foot slice more than this many times
the top's widest."""


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


def _treads(up: np.ndarray, column: np.ndarray, rise: np.ndarray, height: float) -> np.ndarray:
    """(N,) bool: the treads a ``_flight`` column holds between its ground and its neighbour's level
    (``rise``), left out as ground: its points from half a ``GROUND_BAND`` up to that level fill at most
    ``TREAD_FILL`` of the ``GROUND_TOL``-thin slices there, and nothing stands on them (the band over the
    level's band holds under a tenth as many points); the level's band goes with them. Where the ground
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
    ok = (filled <= TREAD_FILL * room) & free & (held >= 5)
    return (own | level) & ok[column]


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


AUTO_Y_CONFIDENCE = 0.75
"""With ``up='auto'`` a file is turned from Y up only when ``guess_up_axis`` says 'y' this surely."""


def auto_up(guess: UpGuess) -> str:
    """The way up ``up='auto'`` reads a file with: the guess on Y only at ``AUTO_Y_CONFIDENCE``, else
    Z, upside down or not as the guess found it along Z."""
    on_y = guess.direction.startswith("y") and guess.confidence >= AUTO_Y_CONFIDENCE
    return guess.direction if on_y else guess.z_direction
