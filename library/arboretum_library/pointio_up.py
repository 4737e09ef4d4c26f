"""The way up of a raw scan, numpy only: ``guess_up`` (+Z, +Y, or either upside down), the turns to Z up,
``trunk_on_top`` (a note for a file that may stand upside down) and ``auto_up`` (the way ``--up auto`` reads).

Here: the decision and the shapes it scores along each axis (``_way_up``, ``_upright_score``: taller than
wide, narrow at the foot, round in plan; ``_upside_down``: ground at the top end with a trunk on it). The
ground under an axis is read by ``pointio_ground`` (``ground_band``, re-exported here), a wall or a fence
beside the tree by ``pointio_wall``. Split out of ``pointio_spatial`` (session 19), which keeps the trunk
base, thinning and spacing; ``pointio`` re-exports both. Split in three in session 24 (helper-173).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .pointio_ground import (
    GROUND_CELLS,
    STEP_COLUMNS,
    _band,
    _columns,
    _ground,
    _largest_extent,
    _spread,
    ground_band,
)
from .pointio_wall import _wall_on_ground, _walls_beside
from .repeats import distinct_rows

__all__ = [
    "AUTO_Y_CONFIDENCE",
    "UP_DIRECTIONS",
    "UpGuess",
    "auto_up",
    "ground_band",
    "guess_up",
    "guess_up_axis",
    "trunk_on_top",
    "turn_from_zup",
    "turn_to_zup",
]


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
    21: 292 of helper-140's 1,728 wall files wrong, 27 now). Such a wall is taken only when the other
    axis's ground is gone without it (``_walls_beside``: else it is that ground seen edge on); with none
    taken, a wall standing on the ground of an axis is left out of that axis's score (``_wall_on_ground``,
    sessions 24-25). Trees are taller than wide, narrow at the foot and round in plan. X is never a
    candidate; a tie goes to Z. See docs/scan-input.md for limits.
    """
    pts = _sample(points)
    z_way, s_z, z_ground, z_any, z_bonus = _way_up(pts, 2)
    y_way, s_y, _, y_any, y_bonus = _way_up(pts, 1)
    axes = ((2, z_way, z_bonus, z_any), (1, y_way, y_bonus, y_any))
    wall = _walls_beside(pts, axes) if not (z_any and y_any) else None
    if wall is not None:  # scored without the wall; an axis whose "ground" it was loses the bonus
        s_z = s_z - z_bonus if z_any else _upright_score(pts[~wall], 2, None)
        s_y = s_y - y_bonus if y_any else _upright_score(pts[~wall], 1, None)
    else:  # a wall may stand on one axis's ground (its face the other's ground, if that has any)
        standing = _wall_on_ground(pts, axes)
        if standing is not None:  # scored without the wall, its ground found again
            axis, rest = standing
            score = _upright_score(rest, axis, _ground(rest, axis))
            s_z, s_y = (score, s_y - y_bonus) if axis == 2 else (s_z - z_bonus, score)
    confidence = float(1.0 / (1.0 + np.exp(-2.0 * min(abs(s_z - s_y), 20.0))))
    return UpGuess(y_way if s_y > s_z else z_way, confidence, z_way, z_ground)


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


GROUND_BONUS = 1.0
"""Added to the score of an axis with ground under it and more than ground above: ground lies under a
tree, so seen from the side (the other axis) it is a wall, which still reads as a tall, narrow-footed
shape."""


SLAB_RATIO = 0.1
"""Footprint thinner than this fraction of its length and of the height: the cloud lies on its side."""


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
    trunk = _hidden_trunk(h, across, hi - lo, width, 2.0 * _spread(across[h <= lo + 0.1 * (hi - lo)]))
    elongation = max(hi - lo, eps) / max(width, eps)
    narrow = min(max(trunk / max(width, eps), 0.01), 100.0)
    return float(np.log(elongation) - 0.75 * np.log(narrow) + 4.0 * np.log(_footprint(across, hi - lo, eps)) + bonus)


FOOT_HIDDEN, FOOT_HELD, FOOT_SPARSE = 0.9, 20, 0.01
"""A trunk hidden under the low end of the extent (``_hidden_trunk``): looked for when the foot slice is at
least this fraction of the crown's width (no narrowing seen at all); the lowest tenth of the height from
the lowest point holds at least this many points and at most this share of them (the guiding default
tree's trunk: 108 points, 0.43 %; a wall's leftover beside the harmonic walnut seen from the side, which
is no trunk: 458 points, 1.9 %)."""


FOOT_UNDER = 0.2
"""... and its middle (median across the axis) lies within this fraction of the crown's width of the whole
cloud's middle: a trunk stands under its crown (the guiding default tree's: 0.055-0.063). The end of a wall
beside a tree without ground, seen along the wall or left over once its core is out, lay 0.29-0.58 off
and turned 34 of helper-185's 1,728 wall files, read right before ``_hidden_trunk``, wrong (the harmonic
walnut, apple, cherry and pine, leaf-off most of them; none of its 5,760 terrace and 960 hummock files)."""


def _hidden_trunk(h: np.ndarray, across: np.ndarray, height: float, width: float, foot: float) -> float:
    """The trunk's width for ``_upright_score``: ``foot`` (the width of the lowest tenth of ``height`` from
    the 0.5 percentile), or, when that is ``FOOT_HIDDEN`` of the crown's ``width`` or more, the width of the
    lowest tenth from the lowest point where that is a trunk the percentile cut off: ``FOOT_HELD`` points
    at least, ``FOOT_SPARSE`` of them at most, narrower than ``TRUNK_NARROW`` of ``height``, standing under
    the crown (``FOOT_UNDER``). The guiding
    default tree's trunk is 12 % of its height but holds 0.56 % of the points once the ground band took
    its foot: the 0.5 percentile lay at the crown's base, the foot slice was crown (1.05 times its width),
    and on flat ground its Y-up files read Z (Y at 0.686-0.687, session 25)."""
    if not foot >= FOOT_HIDDEN * width:
        return foot
    low = h <= h.min() + 0.1 * height
    if not FOOT_HELD <= low.sum() <= FOOT_SPARSE * len(h):
        return foot
    trunk = 2.0 * _spread(across[low])
    off = float(np.hypot(*(np.median(across[low], axis=0) - np.median(across, axis=0))))
    return trunk if trunk < TRUNK_NARROW * height and off <= FOOT_UNDER * width else foot


def _footprint(across: np.ndarray, height: float, eps: float) -> float:
    """min(1, (thin side of the footprint / the smaller of its long side and ``height``) / SLAB_RATIO):
    below 1 for a slab standing on its edge (a ground disc read with the wrong up axis), whose footprint
    is a line and which is as tall as it is long; a crown's is round, and a row of trees, whose footprint
    is a line too, is much lower than long and as deep as it is tall."""
    ext = np.percentile(across, 99.5, axis=0) - np.percentile(across, 0.5, axis=0)
    return min(1.0, max(float(ext.min()), eps) / max(min(float(ext.max()), height), eps) / SLAB_RATIO)


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


FOOT_RATIO = 3.0
"""``trunk_on_top`` (a note, never a turn): the lowest end's narrowest foot slice more than this many times
the top's widest."""


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


AUTO_Y_CONFIDENCE = 0.75
"""With ``up='auto'`` a file is turned from Y up only when ``guess_up_axis`` says 'y' this surely."""


def auto_up(guess: UpGuess) -> str:
    """The way up ``up='auto'`` reads a file with: the guess on Y only at ``AUTO_Y_CONFIDENCE``, else
    Z, upside down or not as the guess found it along Z."""
    on_y = guess.direction.startswith("y") and guess.confidence >= AUTO_Y_CONFIDENCE
    return guess.direction if on_y else guess.z_direction
