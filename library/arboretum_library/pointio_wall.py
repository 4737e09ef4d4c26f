"""A wall or a fence beside a tree, numpy only: ``_wall`` (its points, along an axis with no ground) and
``_wall_on_ground`` (a wall standing on the ground of one axis whose face the other axis took for ground).

``pointio_up.guess_up`` scores an axis without the wall found here: a wall's length read as a tree's
height turned it on its side. Split out of ``pointio_up`` in session 24 (helper-175).
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


WALL_GROUNDED = 0.9
"""A wall found along an axis with ground (``_wall_on_ground``) with at least this share of its points in
that axis's ground band is the ground seen edge on, not a wall (the pine scan's own ground: 1.0; walls
3 heights long standing on stairs: 0.44-0.72)."""


def _wall_on_ground(pts: np.ndarray, axes: tuple) -> tuple[int, np.ndarray] | None:
    """(axis, cloud) of the one axis (``axes``: (axis, way up, ``GROUND_BONUS`` in its score), both with
    ground at some end) with ground under it along which a wall stands beside the tree (``_wall``, the
    cloud turned that way up; not ``WALL_GROUNDED`` in its ground band) whose other axis has no ground
    left without it (that ground was the wall's face), and the cloud turned that way up without the wall
    (``guess_up`` scores it, its ground found again); None when there is none, or one along each (ground
    seen edge on may pass for a wall: which is which is not told). Stairs beside a wall 3 heights long
    facing Y: seen along Y the wall's face is ground, so the wall search did not run, and the wall kept in
    Z's score (its length the crown's width, its foot the trunk's) read the tree on its side (helper-154's
    80 files: 70 wrong)."""
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
        found.append((axis, turned[~wall]))
    return found[0] if len(found) == 1 else None


def _turned(pts: np.ndarray, axis: int, way: str) -> np.ndarray:
    """``pts`` with ``axis`` negated when ``way`` is upside down ('z-down', 'y-down'), else itself."""
    if not way.endswith("-down"):
        return pts
    flipped = pts.copy()
    flipped[:, axis] *= -1.0
    return flipped
