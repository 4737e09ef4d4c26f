"""A wall or a fence beside a tree, numpy only: ``_wall`` (its points, along an axis with no ground) and
``_wall_on_ground`` (a wall standing on the ground of one axis whose face the other axis took for ground).

``pointio_up.guess_up`` scores an axis without the wall found here: a wall's length read as a tree's
height turned it on its side. Split out of ``pointio_up`` in session 24 (helper-173).
"""

from __future__ import annotations

import numpy as np

from .pointio_ground import _ground, _largest_extent

WALL_BAND, WALL_SHARE, WALL_THIN, WALL_LOW = 0.01, 0.05, 0.5, 0.5
"""A wall beside a tree with no ground (``_wall``): the points within this fraction of the largest extent
of a line in the footprint; its thin core (a quarter of that) holds at least this share of the points
and this share of the band's, 90 % of them in this lowest fraction of the extent along the axis. A wall
one tree height long, 0.3 % of it thick, holds 0.53-0.59 of its band in its core (0.6 until session 21
missed it); a slice of crown spread evenly across the band holds a quarter."""


WALL_TRIES, WALL_SAMPLE, WALL_KEEP = 100, 4000, 20
"""``_wall`` tries this many lines through two points of a fixed random sample of this many; a wall's
core holds, and leaves, at least this many points."""


WALL_MORE = 300
"""... and this many lines more, drawn after those (the first ``WALL_TRIES`` are the lines tried until
session 25). Both points of a line lie on a wall holding a tenth of the lower half's points once in 100
tries, so 100 lines miss it 37 times in 100 and 400 lines twice (helper-177: a wall 3 heights long on
stairs beside scan 07 or the harmonic cherry was missed; 8 of 264 stairs-and-wall files more read right).
When the best of all the lines is no wall, the best of the first ``WALL_TRIES`` is tried too: the best of
400 was sometimes a line through crown and wall that failed ``WALL_THIN`` or ``WALL_LOW`` where the first
100 had found the wall (helper-185: 5 of 1,728 wall files beside the leaf-off harmonic walnut newly wrong)."""


def _wall(pts: np.ndarray, axis: int) -> np.ndarray:
    """(N,) bool: the points of a wall (or a fence) standing along ``axis`` beside the tree, all False
    when none. On ``WALL_SAMPLE`` points drawn at random (fixed; with repeats; all of a smaller cloud),
    the line in the footprint across ``axis`` holding the most of the lower half's points within a quarter
    of ``WALL_BAND`` (``WALL_TRIES`` + ``WALL_MORE`` lines through two of them; failing that, the best of
    the first ``WALL_TRIES``, ``_wall_along``) is a wall when that thin band
    holds ``WALL_SHARE`` of the points and ``WALL_THIN`` of those within ``WALL_BAND`` (a wall is thin; a
    slice of crown is not), and 90 % of them lie in the lowest ``WALL_LOW`` of the extent along ``axis`` (a wall
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
    a = np.concatenate([a, low[rng.integers(0, len(low), WALL_MORE)]])  # the first lines as before
    b = np.concatenate([b, low[rng.integers(0, len(low), WALL_MORE)]])
    d = b - a
    norm = np.hypot(d[:, 0], d[:, 1])
    if not (norm > 0).any():
        return none
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)[norm > 0] / norm[norm > 0, None]
    off = np.einsum("ij,ij->i", n, a[norm > 0])
    band = WALL_BAND * _largest_extent(pts)
    held = (np.abs(low @ n.T - off) < 0.25 * band).sum(axis=0)
    first = (norm > 0)[:WALL_TRIES].sum()  # the lines tried until session 25
    for best in dict.fromkeys([int(np.argmax(held)), int(np.argmax(held[:first])) if first else -1]):
        wall = _wall_along(pts, axis, sub, n[best], off[best], band, top) if best >= 0 else none
        if wall.any():
            return wall
    return none


def _wall_along(pts: np.ndarray, axis: int, sub: np.ndarray, normal: np.ndarray, off: float, band: float,
                top: float) -> np.ndarray:
    """(N,) bool: ``_wall``'s test of the line ``normal`` . p = ``off`` across ``axis`` (on the sample ``sub``),
    all False when it is no wall; else the wall's points."""
    none = np.zeros(len(pts), dtype=bool)
    dist = np.abs(np.delete(sub, axis, axis=1) @ normal - off)
    thin = dist < 0.25 * band
    if thin.mean() < WALL_SHARE or thin.sum() < max(WALL_KEEP, WALL_THIN * (dist < band).sum()):
        return none
    if (sub[thin, axis] < top).mean() < 0.9:
        return none
    wall = (np.abs(np.delete(pts, axis, axis=1) @ normal - off) < band) & (pts[:, axis] < top)
    return wall if (~wall).sum() >= WALL_KEEP else none


WALL_GROUNDED = 0.9
"""A wall found along an axis with ground (``_wall_on_ground``) with at least this share of its points in
that axis's ground band is the ground seen edge on, not a wall (the pine scan's own ground: 1.0; walls
3 heights long standing on stairs: 0.44-0.72)."""


def _walls_beside(pts: np.ndarray, axes: tuple) -> np.ndarray | None:
    """(N,) bool: the walls (``_wall``) standing along the axes without ground at either end (``axes``: (axis,
    way up, ``GROUND_BONUS`` in its score, ground at either end) for Z and Y, ground along one at most),
    None when there is none. A wall found along one axis while the other has ground under it is taken
    only when that ground is gone without it, its whole face up to its top (``_ground_was_face``,
    ``_whole_face``: it was the wall's face); else it is
    that ground's lowest level seen edge on (stairs along Y, the wall facing X: seen along Y the flat
    ground below the flight is a thin line low along Y, and Z lost its bonus: 45 of 88 files wrong)."""
    wall = np.zeros(len(pts), dtype=bool)
    for k, (axis, _, _, any_ground) in enumerate(axes):
        if any_ground:
            continue
        found = _wall(pts, axis)
        if found.any() and _ground_was_face(pts, _whole_face(pts, found, axis), axes[1 - k]):
            wall |= found
    return wall if wall.any() else None


def _whole_face(pts: np.ndarray, wall: np.ndarray, axis: int) -> np.ndarray:
    """(N,) bool: ``wall`` and the points within ``WALL_BAND`` of its line across ``axis`` above it: the
    wall's face up to its top (``_wall`` keeps only what lies in the lowest ``WALL_LOW`` of the extent; a
    wall half a tree's height tall left 307 points of its top over it, and the other axis still found
    ground there: helper-185, the leaf-off eucalyptus beside such a wall, 3 of 1,728 files newly wrong)."""
    xy = np.delete(pts, axis, axis=1)
    mid = xy[wall].mean(axis=0)
    normal = np.linalg.svd(xy[wall] - mid, full_matrices=False)[2][-1]
    return wall | (np.abs((xy - mid) @ normal) < WALL_BAND * _largest_extent(pts))


def _ground_was_face(pts: np.ndarray, wall: np.ndarray, other: tuple) -> bool:
    """Whether the ground under the ``other`` axis ((axis, way up, ``GROUND_BONUS``, ground at either end))
    was the face of ``wall``: none is left under it without the wall (True when it had no bonus to lose)."""
    axis, way, bonus, _ = other
    return not bonus or _ground(_turned(pts, axis, way)[~wall], axis) is None


def _wall_on_ground(pts: np.ndarray, axes: tuple) -> tuple[int, np.ndarray] | None:
    """(axis, cloud) of the one axis (``axes``: (axis, way up, ``GROUND_BONUS`` in its score, ground at
    either end) for Z and Y) with ground under it along which a wall stands beside the tree (``_wall``,
    the cloud turned that way up; not ``WALL_GROUNDED`` in its ground band) whose other axis has no ground
    left without it (that ground was the wall's face; an axis without ground at either end has none to
    lose), and the cloud turned that way up without the wall (``guess_up`` scores it, its ground found
    again); None when there is none, or one along each (ground seen edge on may pass for a wall: which is
    which is not told). Stairs beside a wall 3 heights long facing Y: seen along Y the wall's face is
    ground, so the wall search did not run, and the wall kept in Z's score (its length the crown's width,
    its foot the trunk's) read the tree on its side (helper-154's 80 files: 70 wrong). The same stairs
    along Y, the wall facing X, leave Y without ground: the wall standing on Z's is looked for too (session
    25)."""
    found = []
    for k, (axis, way, bonus, _) in enumerate(axes):
        if not bonus:
            continue
        turned = _turned(pts, axis, way)
        wall = _wall(turned, axis)
        if not wall.any():
            continue
        ground = _ground(turned, axis)  # not None: the bonus is for it
        if ground is None or (wall & ground).sum() >= WALL_GROUNDED * wall.sum():
            continue
        other, other_way, _, other_any = axes[1 - k]
        if other_any and _ground(_turned(pts, other, other_way)[~wall], other) is not None:
            continue  # the other axis's ground was not the wall's face
        found.append((axis, turned[~wall]))
    return found[0] if len(found) == 1 else None


def _turned(pts: np.ndarray, axis: int, way: str) -> np.ndarray:
    """``pts`` with ``axis`` negated when ``way`` is upside down ('z-down', 'y-down'), else itself."""
    if not way.endswith("-down"):
        return pts
    flipped = pts.copy()
    flipped[:, axis] *= -1.0
    return flipped
