"""Whether a surface is the ground, and what it cuts, for ``ground.find_ground``: ``_surface`` takes the
first of ``ground_surface._candidates`` whose cut (``_cut``) leaves few points below it and the trunk
standing over a ground wider than it, with no trunk going on under it (``_trunk_below``, ``_trunk_under``:
a groundless tree's lowest branch layer is no ground; ``_plate``: a root plate under the ground is no
trunk). ``_buried`` reads a first surface refused only for the outliers under it, ``_mirrored`` the points
under a surface that are the tree's mirror (multipath), not counted below it. Split out of ``ground`` in
session 25.
"""

from __future__ import annotations

import numpy as np

from .ground_surface import Found, Ground, _below, _candidates, body_span
from .trunkbase_links import plan_radius

GROUND_WIDER = 3.0
"""The ground spreads at least this many times wider than the trunk just above it."""
GROUND_SHARE = 0.005
"""A ground holds at least this share of the points within half of ``ground_band`` of it (scan 10's
patch 2.5 m wide: 3.8 %; the floor of 3 % outliers strewn in a box under it, whose sparse slices made
the real ground the "trunk": 0.04 %)."""
GROUND_TRUNK = 0.5
"""A ground has no trunk going on below it (``_trunk_below``): refused when a narrow column of points
rises from its foot (the lowest 15 slices of what lies under it, ``GROUND_TRUNK_DEEP`` slices or more
down) to its band holding from this share to its inverse of what the same column holds in slices 3-17
above it (a tree with no ground, a trunk of 300-500 points and dense flat branch layers had its lowest
layer, 18-24 % of the height up the trunk, cut as the ground in 37 of 48 clouds)."""
GROUND_TRUNK_DEEP = 20
"""``_trunk_below`` looks only at a column reaching this many slices (``ground_band`` / 3 of the height
over the ground each: 10 % of it at the default band) or more under the ground: the trunk under a
groundless tree's lowest branch layer goes down 18-24 % of the height, but a trunk mirrored in a
puddle, a root plate seen 0.5-0.8 m under the ground, or a post in a hole, under a 10 m tree, reach
10-16 slices and were refused as trunks (helper-151: 8 of 24 mirrored trunks, 2 of 3 root plates). A
lowest layer 9 % of the height up or more still reaches it; a post 1.2 m under a 10 m tree's ground
does too, and is refused (a root plate that deep no longer is: ``_plate``)."""
GROUND_PLATE = 2.0
"""``_plate``: a column under a ground whose foot spreads this many times wider than the same
column over the ground is no trunk going on below it (a root plate 0.25 wide under a trunk 0.1 wide,
1.2-1.5 m under a 10 m tree's ground, had the ground refused in 7 of 10 draws)."""
GROUND_UNSEEN = 5
"""``_trunk_below``'s foot (its lowest 15 slices) does not count the empty slices of a stretch of this
many or more (a trunk unseen for a stretch; a trunk of 300 points 20 tall, 1.35 a slice, leaves 5 empty
in a row about once in a thousand)."""
GROUND_MIRROR = 0.75
"""``_mirrored``: at least this share of the points under a ground land on the cloud above it when
mirrored in it, for them to be taken for the tree's mirror (multipath)."""
GROUND_MIRROR_WEAK = 0.25
"""``_mirrored``: the points that land hold at most this share of the points over the ground within the
landing distance of their images: an echo is sparser than what it mirrors (multipath: 0.2-5 % of a
tree's points). A groundless pole with equal flat whorls 1 m apart mirrors whorl onto whorl and trunk
onto trunk in the plane of a whorl, as dense under as over it, and was cut 5.2 m up (helper-163's
review: 10 of 360 such clouds)."""
MIRROR_SAMPLE = 500
"""``_mirrored`` first mirrors every (n // this)-th point under the ground, and stops when under
``GROUND_MIRROR`` - 0.15 of those land (a groundless apple spent 45-49 ms a surface mirroring 30,000 points
of which under 4 % landed: helper-163)."""


def _spread(q: np.ndarray) -> float:
    """Median plan-view distance of ``q`` (M, 3) from its median; inf for fewer than 5 points."""
    return np.inf if len(q) < 5 else plan_radius(q, 50)


def _surface(pts: np.ndarray, low: np.ndarray, band_frac: float, inside: np.ndarray,
             h: float, counted: np.ndarray | None = None) -> tuple[Found, Found | None, np.ndarray | None]:
    """(N,) bool ground points of ``pts`` (N, 3) and the ``Ground`` through the column samples ``low``
    (M, 3), or no points and None (``find_ground``; ``h``: the height the scales come from; ``counted``:
    (N,) bool, the points counted below a ground, all when None); the
    first surface refused only for holding under ``GROUND_SHARE`` of the points, or None
    (``find_ground``'s last resort: found here once, not searched for again); and the first surface's
    heights under ``pts`` (N,), or None when no surface was fitted (``_buried`` reads them).

    The ground is ``ground_plane``, or ``ground_curve`` when that fits ``GROUND_GAIN`` more of the
    column minima or the plane is refused: accepted (``_cut``) when at most ``GROUND_BELOW`` of the
    points lie below it and the points within half of ``band_frac`` of the height of it spread
    ``GROUND_WIDER`` times wider than the trunk. When neither is, each is tried once more following the
    dips of its columns (``_dips``: a ditch), if then at most ``GROUND_BELOW`` of the points lie
    ``GROUND_DIP`` of the height or more below it.
    """
    sparse, first = None, None
    for ground, under in _candidates(pts, low, band_frac, h, counted):
        first = under if first is None else first
        cut = _cut(pts, under, band_frac, inside, counted)
        if cut is None:
            continue
        if cut[1]:
            return (cut[0], ground), sparse, first
        if sparse is None:
            sparse = cut[0], ground
    return (np.zeros(len(pts), bool), None), sparse, first


def _buried(pts: np.ndarray, under: np.ndarray | None, band_frac: float, inside: np.ndarray) -> bool:
    """Whether the first search's first surface (its heights ``under`` (N,) ``pts`` (N, 3), or None) is a
    ground but for the points below it (``_cut`` with none of them counted, ``GROUND_SHARE`` held): a
    sparse ground (3,000 points 30 wide under a 20 m pine, about one a column) among 10-20 % uniform
    outliers, 1.3-2.7 % of the points strewn under it, whose columns hold too few points for ``held``;
    ``_search`` then tries ``_narrow_surface`` on it as on a narrow cloud."""
    if under is None:
        return False
    up = pts[:, 2] - under
    if not _below(up < -band_frac * float(up[inside].max()) / 2, None):  # refused for something else (quick)
        return False
    cut = _cut(pts, under, band_frac, inside, np.zeros(len(pts), bool))
    return cut is not None and cut[1]


def _cut(pts: np.ndarray, under: np.ndarray, band_frac: float, inside: np.ndarray,
         counted: np.ndarray | None = None) -> tuple[np.ndarray, bool] | None:
    """(N,) bool: the points of ``pts`` (N, 3) cut as ground over the ground heights ``under`` (N,), and
    whether it holds ``GROUND_SHARE`` of the points within ``band_frac`` / 2 of it; None when it is no
    ground (``find_ground``; ``inside``: the points that set the height).

    The trunk's spread is the narrowest of the slices ``band_frac`` / 3 thick from ``band_frac`` to
    6 ``band_frac`` above the ground (low branches widen some), or to 10 ``band_frac`` when the ground is
    not wider than that (grass as tall as 6 ``band_frac``). Cut: everything below the first slice
    from ``band_frac`` up that is trunk-wide again (at most twice the trunk's spread), grass, shrubs, a
    rough surface and points under the ground with it, but for the trunk above ``band_frac``: the points
    within twice that slice's spread of the median of the trunk's narrowest slice (understory shrubs cut
    the trunk with them, and the root went 5.5-6 % of the height up it; round the median of the slice
    at the cut, which held the top of a boulder by the trunk, the boulder was kept too and drew the root
    up to 7.6 % of the height aside).
    """
    up = pts[:, 2] - under  # height above the ground
    step = band_frac * float(up[inside].max()) / 3  # of the tree's height: a slope's rise is not the tree's
    near = np.flatnonzero((up > -step) & (up < 30 * step))
    slab = np.floor(up[near] / step).astype(np.int64)

    def spread(k: int) -> float:
        return _spread(pts[near[slab == k]])

    slices = {k: spread(k) for k in range(3, 18)}
    band = np.abs(up) < 1.5 * step
    wide = _spread(pts[band])
    if wide < GROUND_WIDER * min(slices.values()):  # grass up to 9 % of the height: the trunk shows above it
        slices.update({k: spread(k) for k in range(18, 30)})
    trunk = min(slices.values())
    if _below(up < -1.5 * step, counted) or not np.isfinite(trunk) or wide < GROUND_WIDER * trunk:
        return None
    if _trunk_below(pts, up, step, wide):
        return None
    cut = next((k for k in range(3, 30) if (slices[k] if k in slices else spread(k)) < 2 * trunk), 3)
    ground = up < cut * step
    if cut >= 6:  # shrubs or grass round the trunk, twice the band tall: the trunk in them is kept
        ring = pts[near[slab == min(slices, key=slices.get)]]  # the trunk alone: no boulder's top in it
        centre, reach = np.median(ring[:, :2], axis=0), 2 * spread(cut)
        ground &= ~((up >= 3 * step) & (((pts[:, :2] - centre) ** 2).sum(axis=1) < reach ** 2))
    return ground, bool(band.sum() >= GROUND_SHARE * len(pts))


def _trunk_below(pts: np.ndarray, up: np.ndarray, step: float, wide: float) -> bool:
    """Whether the trunk goes on under a ground, down to its own foot (``_cut``; ``up``: (N,) heights of
    ``pts`` (N, 3) above it, ``step``: a slice's thickness, ``wide``: the ground's spread): the points
    under the band reach ``GROUND_TRUNK_DEEP`` slices down, the 15 lowest slices of them (the foot,
    ``_lowest_slices``: a stretch of ``GROUND_UNSEEN`` empty slices or more not counted), at least 10 points, are a column wider than none (a plumb line's repeated xy) and narrower than a
    ground (under ``wide`` / ``GROUND_WIDER``), the points within twice its spread of its axis rise from
    it to the band with no gap of 15 slices, and the same column holds at least 10 points in slices 3-17
    above the ground, as many as the foot within a factor of 1 / ``GROUND_TRUNK``, and the foot spreads
    under ``GROUND_PLATE`` times as wide as that column (``_plate``: a root plate). Strays under a ground
    (outliers, multipath echoes) spread over its whole area, a clump apart from it leaves a gap, the
    bottom of a hollow or a ditch has no trunk over it; a trunk mirrored in a puddle or a root plate
    seen under the ground does not reach so deep."""
    under = np.flatnonzero(up < -1.5 * step)
    if len(under) < 10 or up[under].min() > -GROUND_TRUNK_DEEP * step:
        return False
    foot = pts[under[_lowest_slices(up[under], step, 15)]]
    spread = _spread(foot)
    if len(foot) < 10 or not 0 < spread < wide / GROUND_WIDER:  # strays spread like the ground over its area
        return False
    centre = np.median(foot[:, :2], axis=0)
    high = np.flatnonzero((up >= 3 * step) & (up < 18 * step))

    def column(idx: np.ndarray) -> np.ndarray:
        return idx[((pts[idx, :2] - centre) ** 2).sum(axis=1) < (2 * spread) ** 2]

    rise = np.sort(up[column(under)])
    if np.diff(np.r_[rise, -1.5 * step]).max() >= 15 * step:
        return False
    over = column(high)
    trunk = len(over)  # none over the bottom of a hollow
    if not (trunk >= 10 and GROUND_TRUNK * trunk <= len(foot) <= trunk / GROUND_TRUNK):
        return False
    return not _plate(pts, foot, over)


def _plate(pts: np.ndarray, foot: np.ndarray, over: np.ndarray) -> bool:
    """Whether the column under a ground (its ``foot`` (F, 3), and ``over``: the indices of ``pts`` (N, 3)
    in the same column 3-17 slices over the ground) is no trunk of the tree over it (``_trunk_below``):
    its foot spreads ``GROUND_PLATE`` times wider than the column over the ground (a root plate under
    the trunk). A groundless tree's trunk under its lowest branch layer spreads like the trunk over it."""
    return bool(_spread(foot) > GROUND_PLATE * _spread(pts[over]))


def _lowest_slices(up: np.ndarray, step: float, k: int) -> np.ndarray:
    """(M,) bool: the heights ``up`` (M,) in the lowest ``k`` slices ``step`` thick from their lowest, the
    empty slices of a stretch of ``GROUND_UNSEEN`` or more not counted (``_trunk_below``'s foot: a
    groundless layered tree's trunk unseen 0.5-1.3 m up left its lowest 15 slices, from its foot,
    22-54 points against 56-70 over the layer, and the layer was cut as the ground). Without such a
    stretch: the lowest ``k`` slices."""
    slab = np.floor((up - up.min()) / step).astype(np.int64)
    held = np.unique(slab)
    empty = np.diff(held) - 1
    counted = held - np.r_[0, np.cumsum(np.where(empty >= GROUND_UNSEEN, empty, 0))]
    return slab <= held[counted < k].max()


def _trunk_under(pts: np.ndarray, surface: Ground, band_frac: float) -> bool:
    """``_trunk_below`` for all of ``pts`` (N, 3) under ``surface``, found among the points not set apart
    (``find_ground``), with ``_cut``'s slices and ground spread."""
    up = pts[:, 2] - surface.height(pts[:, :2])
    lo, hi = body_span(pts[:, 2])
    step = band_frac * float(up[(pts[:, 2] >= lo) & (pts[:, 2] <= hi)].max()) / 3
    return _trunk_below(pts, up, step, _spread(pts[np.abs(up) < 1.5 * step]))


def _mirrored(pts: np.ndarray, under: np.ndarray, tol: float) -> np.ndarray:
    """(N,) bool: the points of ``pts`` (N, 3) more than ``tol`` below their ground heights ``under`` (N,)
    that, mirrored in it, land within ``tol`` of a point above it, when at least ``GROUND_MIRROR`` of
    those below do, spread at least half as wide as those above and reach at least half as deep as those
    stand tall (a tree's mirror, not a trunk going on under a crown's underside, which mirrors onto
    itself, nor the foot of a dense leafy tree with no ground, which lands on its like, nor outliers
    strewn under a ground); else none."""
    from scipy.spatial import cKDTree

    up = pts[:, 2] - under
    below, above = np.flatnonzero(up < -tol), np.flatnonzero(up > tol)
    none = np.zeros(len(pts), bool)
    if len(below) < 10 or len(above) < 10 or -up[below].min() < 0.5 * up[above].max():
        return none
    tree = cKDTree(pts[above])
    sample = below[:: max(1, len(below) // MIRROR_SAMPLE)]
    if (_landing(tree, pts[sample], under[sample], tol) <= tol).mean() < GROUND_MIRROR - 0.15:
        return none  # most of them land nowhere: not worth them all
    land = below[_landing(tree, pts[below], under[below], tol) <= tol]
    if len(land) < GROUND_MIRROR * len(below) or _spread(pts[land]) < 0.5 * _spread(pts[above]) \
            or -up[land].min() < 0.5 * up[above].max():
        return none
    image = pts[land] * [1, 1, -1] + np.c_[np.zeros((len(land), 2)), 2 * under[land]]
    covered = np.isfinite(cKDTree(image).query(pts[above], distance_upper_bound=tol)[0]).sum()
    if len(land) > GROUND_MIRROR_WEAK * covered:  # as dense as what it mirrors: layers of the tree, no echo
        return none
    none[land] = True
    return none


def _landing(tree, q: np.ndarray, under: np.ndarray, tol: float) -> np.ndarray:
    """(M,) distance from each point of ``q`` (M, 3) mirrored in its ground height ``under`` (M,) to the
    nearest point of ``tree`` (inf beyond ``tol``)."""
    image = q * [1, 1, -1] + np.c_[np.zeros((len(q), 2)), 2 * under]
    return tree.query(image, distance_upper_bound=tol)[0]
