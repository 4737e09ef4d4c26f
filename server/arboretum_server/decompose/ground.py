"""Ground under a scanned tree (VRTree Appendix A: "remove the ground when present"): ``find_ground`` cuts a
plane, or a gently curved surface, with the dips of a ditch, grass, shrubs round the trunk and strays
below it, and refuses a crown's underside or a drooping crown. Split out of ``preprocess`` (session 19),
which calls it; docs/decomposition.md, "Ground", has the rules and what was measured.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .trunkbase import plan_radius

GROUND_CELL = 0.02
"""Ground search: the lowest point of each xy column this wide (fraction of the height) samples it."""
GROUND_TILT = 0.5
"""Steepest ground slope searched (rise over run: 27 degrees)."""
GROUND_TRIES = 200
"""RANSAC triples tried for the ground plane."""
GROUND_SAMPLE = 5000
"""RANSAC scores a plane on at most this many column minima (a wide scan has tens of thousands)."""
GROUND_WIDER = 3.0
"""The ground spreads at least this many times wider than the trunk just above it."""
GROUND_BELOW = 0.01
"""At most this fraction of the points lies below the ground (a plane through the underside of a crown
has the trunk below it)."""
GROUND_EDGE = 0.01
"""Far strays are looked for among this share of the lowest and of the highest points (``body_span``)."""
GROUND_FAR = 0.1
"""A gap in z wider than this fraction of the rest's span sets the points beyond it apart (``body_span``)."""
GROUND_SPAN = 1.1
"""The span of z the ground search scales by is at most this many times the 0.1-99.9 percentile span
(``body_span``: outliers strewn above and below the tree, with no gap)."""
GROUND_DIP = 0.03
"""When neither surface is accepted, each column of the ground follows its lowest point down to this
fraction of the height below it (a ditch 1 % deep held more than ``GROUND_BELOW`` of the points)."""
GROUND_HELD = 3
"""``held``: a column's ground sample has this many points of its column just above it (2 let 5 %
uniform outliers hold some of scan 10's columns 2-12 % of the height under its ground, which was then
missed in 8 of 10 draws)."""
GROUND_HELD_MORE = (6, 12, 24)
"""``held``'s counts tried in turn after ``GROUND_HELD``: 10-20 % uniform outliers held each other 3 deep
down to their box's floor under scan 10's ground, which was missed in 9-20 of 20 draws (the root 4-24 %
of the height under it)."""
SCATTER_SAMPLE = 5_000
"""``_many_scattered`` reads the share of scattered points on at most this many of them (their
neighbours found among all the points)."""
GROUND_DITCH = 0.1
"""``_dips`` follows a column deeper than ``GROUND_DIP`` down to this fraction of the height below the
ground when a chain of columns, each at most ``GROUND_WALL`` deeper than the last, leads to it from a
shallow one (a ditch 4 % deep and wide, or 8 % deep, was refused with "no trunk base")."""
GROUND_WALL = 1.0
"""Steepest rise over run between neighbouring columns that ``_dips`` follows down (45 degrees)."""
GROUND_SHARE = 0.005
"""A ground holds at least this share of the points within half of ``ground_band`` of it (scan 10's
patch 2.5 m wide: 3.8 %; the floor of 3 % outliers strewn in a box under it, whose sparse slices made
the real ground the "trunk": 0.04 %)."""
GROUND_GAIN = 0.05
"""A curved ground is tried before the plane when it fits this share of the column minima more."""
GROUND_BEND = 0.15
"""A curved ground rises or falls at most this fraction of the height from its plane part."""
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
GROUND_APART = 0.1
"""At most this share of the points, set apart under the rest by a gap in z of ``GROUND_DIP`` of the
height or more, is looked past first (``_apart_below``): a clump of 2 % of scan 10's points 10 % of the
height under its ground hid its columns, and a strip of 4 % was taken for it (the root 3.3 and 3.2 m
low)."""

GROUND_NARROW = 64
"""A cloud sampled by fewer columns than this (``GROUND_CELL``) is searched once more by fewer held
points (``_narrow_surface``): scan 10, 2.4 m wide (41-49 columns), thinned to 4,000 points with 10-20 %
uniform outliers, held 19 columns, too few to fit, and had no ground (the root 2.6-4.9 % of the height
low). Scan 07 (97-131 columns, no ground) spent 11 ms there with 200."""
GROUND_HELD_FEW = (2, 1)
"""``_narrow_surface``'s held counts, tried in turn."""
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
GROUND_MIRROR_LOW = 0.4
"""``_mirror_surface`` searches again among the points above this fraction of the span (the mirror's
half of it set aside)."""


def _spread(q: np.ndarray) -> float:
    """Median plan-view distance of ``q`` (M, 3) from its median; inf for fewer than 5 points."""
    return np.inf if len(q) < 5 else plan_radius(q, 50)


def body_span(z: np.ndarray) -> tuple[float, float]:
    """Lowest and highest z of ``z`` (N,) once far strays are set apart: among the lowest and the highest
    ``GROUND_EDGE`` of the values, a gap wider than ``GROUND_FAR`` of the span between them sets apart
    everything beyond it (a bird 30 m above a 5 m tree made the ground search's cells and band six times
    too coarse); and neither end lies more than ``GROUND_SPAN`` times the 0.1-99.9 percentile span from
    the other's percentile. Without such strays: the min and the max."""
    zs = np.sort(z)
    n = len(zs)
    k = max(1, int(GROUND_EDGE * n))
    if n < 2 * k + 2:
        return float(zs[0]), float(zs[-1])
    far = GROUND_FAR * float(zs[n - 1 - k] - zs[k])
    top = np.flatnonzero(np.diff(zs[n - 1 - k:]) > far)
    bottom = np.flatnonzero(np.diff(zs[:k + 1]) > far)
    hi = zs[n - 1 - k + top[0]] if len(top) else zs[-1]
    lo = zs[bottom[-1] + 1] if len(bottom) else zs[0]
    p_lo, p_hi = zs[int(0.001 * (n - 1))], zs[int(np.ceil(0.999 * (n - 1)))]
    reach = GROUND_SPAN * (p_hi - p_lo)
    return float(max(lo, p_hi - reach)), float(min(hi, p_lo + reach))


def _columns_low_first(xy: np.ndarray, z: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(order, first): the points ``xy`` (N, 2) sorted by ``cell``-wide column and then by ``z`` (N,), and
    (N,) bool marking each column's first, lowest one. Columns are widened so that no axis holds more
    than 2 ** 20 of them (a cloud far wider than tall overflowed the int64 keys)."""
    cell = max(cell, float(np.ptp(xy, axis=0).max()) / 2 ** 20, 1e-300)
    key = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64)
    key = key[:, 0] * (int(key[:, 1].max()) + 1) + key[:, 1]
    order = np.lexsort((z, key))
    return order, np.r_[True, key[order][1:] != key[order][:-1]]


def held(z: np.ndarray, order: np.ndarray, first: np.ndarray, gap: float,
         k: int = GROUND_HELD) -> tuple[np.ndarray, np.ndarray]:
    """(order, first) of ``_columns_low_first`` (``order``, ``first``: over heights ``z`` (N,)) kept to the
    points that have ``k`` more points of their column within ``gap`` above them (a lone outlier has
    none): each column's ``first`` is then its lowest such point."""
    col = np.cumsum(first) - 1
    zs = z[order]
    ok = np.zeros(len(zs), bool)
    ok[:-k] = (col[k:] == col[:-k]) & (zs[k:] - zs[:-k] < gap)
    col = col[ok]
    return order[ok], np.r_[True, col[1:] != col[:-1]] if len(col) else np.zeros(0, bool)


@dataclass(frozen=True, eq=False)
class Ground:
    """The ground under a tree: the plane z = a x + b y + c, bent by a quadratic about ``centre`` when one
    plane does not fit it (a bowl, a dome, a valley)."""

    plane: np.ndarray
    """(3,) a, b, c."""
    bend: np.ndarray | None = None
    """(3,) the x², x y and y² terms about ``centre``, or None for a plane."""
    centre: np.ndarray | None = None
    """(2,) x, y the bend is measured from."""

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(N,) the ground's z under ``xy`` (N, 2)."""
        z = xy @ self.plane[:2] + self.plane[2]
        if self.bend is None:
            return z
        d = xy - self.centre
        return z + d[:, 0] ** 2 * self.bend[0] + d[:, 0] * d[:, 1] * self.bend[1] + d[:, 1] ** 2 * self.bend[2]


Found = tuple[np.ndarray, "Ground | None"]
"""``find_ground``'s answer: (N,) bool ground points and the ``Ground``, or no points and None."""


def ground_plane(low: np.ndarray, tol: float) -> np.ndarray | None:
    """(a, b, c) of the ground z = a x + b y + c through the column minima ``low`` (M, 3), or None.

    RANSAC (``GROUND_TRIES`` triples, a fixed seed; scored on at most ``GROUND_SAMPLE`` of ``low``): the
    plane, at most ``GROUND_TILT`` steep, that most minima lie within ``tol`` of, refitted by least
    squares to all of them that do.
    """
    if len(low) < 20:
        return None
    rng = np.random.default_rng(0)  # its own: the downsampling stream stays as it was
    some = low if len(low) <= GROUND_SAMPLE else low[rng.choice(len(low), GROUND_SAMPLE, replace=False)]
    best, best_n = None, 0
    for _ in range(GROUND_TRIES):
        a, b, c = some[rng.choice(len(some), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = float(np.linalg.norm(n))
        if norm == 0 or abs(n[2]) < norm / np.hypot(1.0, GROUND_TILT):
            continue
        k = int((np.abs((some - a) @ n) < tol * norm).sum())
        if k > best_n:
            best_n, best = k, (a, n / norm)
    if best is None or best_n < 20:
        return None
    on = np.abs((low - best[0]) @ best[1]) < tol
    coef, *_ = np.linalg.lstsq(np.c_[low[on, :2], np.ones(int(on.sum()))], low[on, 2], rcond=None)
    return coef


def ground_curve(low: np.ndarray, plane: np.ndarray, tol: float, h: float) -> Ground | None:
    """The quadratic ground through the column minima ``low`` (M, 3) grown from ``plane``: fitted by least
    squares to the minima within 8, 4, 2, then 1 ``tol`` of the last fit (a bowl 4.5 % of the height
    deep leaves only a ring of minima within ``tol`` of one plane), or None when it bends more than
    ``GROUND_BEND`` of ``h`` over the minima it fits or fits fewer than 20."""
    centre = np.median(low[:, :2], axis=0)
    d = (low[:, :2] - centre) / h  # scaled: a georeferenced x squared loses its digits
    design = np.c_[d, np.ones(len(low)), d[:, 0] ** 2, d[:, 0] * d[:, 1], d[:, 1] ** 2]
    fit = low[:, :2] @ plane[:2] + plane[2]
    on = np.zeros(len(low), bool)
    for reach in (8, 4, 2, 1):
        on = np.abs(low[:, 2] - fit) < reach * tol
        if on.sum() < 20:
            return None
        a = design[on]
        coef, *_ = np.linalg.lstsq(a.T @ a, a.T @ low[on, 2], rcond=None)  # the normal equations: quick
        fit = design @ coef
    bend = coef[3:] / h ** 2
    if np.ptp(design[on, 3:] @ coef[3:]) > GROUND_BEND * h:
        return None
    slope = coef[:2] / h
    return Ground(np.r_[slope, coef[2] - centre @ slope], bend, centre)


def find_ground(pts: np.ndarray, band_frac: float) -> tuple[np.ndarray, Ground | None]:
    """(N,) bool ground points of ``pts`` (N, 3), flat, sloped or curved, and the ``Ground`` or None when
    there is no ground.

    When a few points lie apart under the rest (``_apart_below``: a clump or a strip of strays), the
    ground is searched for first among the rest (``_search``) and cut with those points when they all
    lie under it and the trunk does not go on down through them (``_trunk_under``: a groundless tree's
    trunk unseen for a stretch under its lowest branch layer was set apart, the layer cut as the ground
    with it); else (no ground, or the lowest step of a terraced ground, which lies beside the others)
    among all the points.
    """
    apart = _apart_below(pts[:, 2])
    if apart is not None:
        ground, surface = _search(pts[~apart], band_frac)
        if surface is not None and (pts[apart, 2] < surface.height(pts[apart, :2])).all() \
                and not _trunk_under(pts, surface, band_frac):
            cut = apart.copy()
            cut[~apart] = ground
            return cut, surface
    return _search(pts, band_frac)


def _apart_below(z: np.ndarray) -> np.ndarray | None:
    """(N,) bool: the heights ``z`` (N,) under the highest gap of ``GROUND_DIP`` of ``body_span``'s height
    or more among its lowest ``GROUND_APART`` (far strays below it with them), or None when there is none.
    Such points are no ground under a tree: a ground has the tree standing on it."""
    lo, hi = body_span(z)
    if hi <= lo:
        return None
    body = z[(z >= lo) & (z <= hi)]
    k = int(GROUND_APART * len(body))
    zs = np.sort(np.partition(body, k)[:k + 1])  # the lowest k + 1 in order, without sorting them all
    gaps = np.flatnonzero(np.diff(zs) >= GROUND_DIP * (hi - lo))
    return z < zs[gaps[-1] + 1] if len(gaps) else None


def _trunk_under(pts: np.ndarray, surface: Ground, band_frac: float) -> bool:
    """``_trunk_below`` for all of ``pts`` (N, 3) under ``surface``, found among the points not set apart
    (``find_ground``), with ``_cut``'s slices and ground spread."""
    up = pts[:, 2] - surface.height(pts[:, :2])
    lo, hi = body_span(pts[:, 2])
    step = band_frac * float(up[(pts[:, 2] >= lo) & (pts[:, 2] <= hi)].max()) / 3
    return _trunk_below(pts, up, step, _spread(pts[np.abs(up) < 1.5 * step]))


def _search(pts: np.ndarray, band_frac: float) -> Found:
    """``find_ground``'s search on ``pts`` (N, 3).

    Scales come from the points between ``body_span``'s (far strays aside) and the ground is sampled by
    the lowest point of each ``GROUND_CELL`` column of them (``_columns_low_first``; ``_surface`` fits and
    checks it). When that finds none and those points reach a column width or more lower than the ones
    with ``GROUND_HELD`` others of their column just above them (``held``), the columns are sampled once
    more by their lowest held point, with the scales taken from the held points: outliers strewn under a
    small ground were the minima of most columns and stretched the span (scan 10, its ground 2.5 m wide,
    with 1-3 % uniform outliers: its ground was kept, the root 4 m under it); when so many outliers hold
    each other that the held points reach the floor too, with more of them held (``GROUND_HELD_MORE``).
    A ground found whose cut leaves points within its band (``_left_in_band``: it followed dips down
    chains of outliers) among many scattered points is searched for again by the held search, which is
    taken when its cut leaves fewer. A cloud too narrow for the held points (``GROUND_NARROW``), or whose
    first surface is a ground but for the points below it (``_buried``: a sparse wide ground among
    outliers), is searched with fewer held (``_narrow_surface``). When that finds none either,
    the first search's surface holding fewer than ``GROUND_SHARE`` of the points (``_surface`` keeps
    it; it is not searched for again) is taken after all: the floor of
    outliers strewn under a tree with no ground, cut with the strays below the tree (scan 07 with
    1.5-3 % of them: the root 20-23 % of the height too low in 8 of 12 draws without it).
    """
    none = np.zeros(len(pts), bool), None
    lo, hi = body_span(pts[:, 2])
    h = hi - lo
    if h <= 0:
        return none
    inside = (pts[:, 2] >= lo) & (pts[:, 2] <= hi)
    body = pts if inside.all() else pts[inside]
    order, first = _columns_low_first(body[:, :2], body[:, 2], GROUND_CELL * h)
    low, tol = body[order[first]], band_frac * h / 2  # the column minima; half the band
    found, sparse, under = _surface(pts, low, band_frac, inside, h)
    if found[1] is None:
        found = _held_surface(pts, body, order, first, band_frac, lo, hi)
    elif _on_strays(body, order, first, found[1], tol):
        held = low[_minima_held(body[:, 2], order, first, tol)]
        found = _held_instead(found, _held_surface(pts, body, order, first, band_frac, lo, hi), low, held, tol)
    elif (left := _left_in_band(pts, found, tol)) and _many_scattered(pts):
        held_found = _held_surface(pts, body, order, first, band_frac, lo, hi)
        if held_found[1] is not None and _left_in_band(pts, held_found, tol) < left:
            found = held_found
    if found[1] is None and sparse is None:  # no surface refused only for its share: maybe a mirror
        found = _mirror_surface(pts, low, band_frac, inside, lo, hi)
    if found[1] is None and (first.sum() < GROUND_NARROW
                             or sparse is None and _buried(pts, under, band_frac, inside)):
        found = _narrow_surface(pts, body, band_frac, lo, hi)
    if found[1] is None and sparse is not None:  # no ground but maybe the sparse floor of strays under the tree
        found = sparse
    return found


GROUND_HELD_SHARE = 0.5
"""``_on_strays``: a ground found among the column minima, under this share of whose minima within the
band of it are held (``held``), may rest on outliers' floor: a plane tilted 0.26-0.45 through it and
one of two pines' patches 2.5 wide, 6 apart, among 5-15 % uniform outliers (0-33 % of its 30-79 minima
held) was taken for the level ground through both (61-74 % held at 5 %), which RANSAC's 200 triples
missed, and the feet stood 0.3-1.5 apart over it (helper-171)."""


def _on_strays(body: np.ndarray, order: np.ndarray, first: np.ndarray, ground: Ground, tol: float) -> bool:
    """Whether the column minima of ``body`` (M, 3) (``order``, ``first``: its columns, lowest first) within
    ``tol`` of ``ground`` are held (``held``: ``GROUND_HELD`` more of their column within ``tol`` above
    them) in under ``GROUND_HELD_SHARE`` of them: ``_search`` then tries the held search first."""
    low = body[order[first]]
    on = np.abs(low[:, 2] - ground.height(low[:, :2])) < tol
    return bool(on.any() and (_minima_held(body[:, 2], order, first, tol) & on).sum() < GROUND_HELD_SHARE * on.sum())


def _left_in_band(pts: np.ndarray, found: Found, tol: float) -> int:
    """How many points of ``pts`` (N, 3) within ``tol`` of the ground of ``found`` (its cut mask and
    ``Ground``) its cut leaves: a cut following its columns' dips (``_dips``) down chains of outliers
    1.8-2.6 under a 10 m wide ground among 10 % uniform outliers left 43-274 of its 3,000 points, read
    as flat patches of other trunks (6 of 40 draws refused, 1 rooted 2.4 off); ``_search`` then tries the
    held search, which counts only held points below a ground and needs no dips there."""
    mask, ground = found
    return int((~mask & (np.abs(pts[:, 2] - ground.height(pts[:, :2])) < tol)).sum())


def _alike(ground: Ground, other: Ground, low: np.ndarray, tol: float) -> bool:
    """Whether ``other`` lies within ``tol`` of ``ground`` (the median over the column minima ``low`` (M, 3)
    within ``tol`` of ``ground``): the same ground, found again by the held search on a sparse ground (a
    disc of 6,000 points a height round the toy tree, 5 % outliers: 9-13 % of its minima held), is not
    taken for it (its cut differs by a few points, and the root moved by 2-3 % of the height)."""
    on = low[np.abs(low[:, 2] - ground.height(low[:, :2])) < tol]
    return bool(np.median(np.abs(ground.height(on[:, :2]) - other.height(on[:, :2]))) < tol)


HELD_GAIN = 2.0
"""``_search`` takes the held search's ground over one on strays (``_on_strays``) only when it carries this
many times as many held minima (``_minima_held``) within the band of it (``_carried``): the level ground
through two pines' patches carried 2.6-27 times as many as the plane tilted through one patch and the
outliers' floor (8-34 against 0-11); over a sparse ground, whose minima few points hold, the plane the held
search fits through shrubs' and the trunk's feet carried 0.02-1.1 times the sparse ground's, and taken, it
moved 7 of 60 right grounds 0.013-0.078 of the height off (helper-172)."""


def _held_instead(found: Found, held_found: Found, low: np.ndarray, held: np.ndarray, tol: float) -> Found:
    """``held_found`` (the held search's) instead of ``found`` (on strays: ``_on_strays``) when it is another
    ground (not ``_alike`` over the column minima ``low`` (M, 3)) carrying ``HELD_GAIN`` times as many of the
    held minima ``held`` (K, 3) within ``tol`` (``_carried``); else ``found``."""
    if held_found[1] is None or _alike(found[1], held_found[1], low, tol):
        return found
    gain = _carried(held_found[1], held, tol) >= HELD_GAIN * max(_carried(found[1], held, tol), 1)
    return held_found if gain else found


def _carried(ground: Ground, low: np.ndarray, tol: float) -> int:
    """How many of the points ``low`` (M, 3) lie within ``tol`` of ``ground``."""
    return int((np.abs(low[:, 2] - ground.height(low[:, :2])) < tol).sum())


def _minima_held(z: np.ndarray, order: np.ndarray, first: np.ndarray, gap: float) -> np.ndarray:
    """(M,) bool for each column's lowest point (``_columns_low_first``'s ``order``, ``first`` over heights
    ``z`` (N,)): ``GROUND_HELD`` more points of its column lie within ``gap`` above it (``held``)."""
    col = np.cumsum(first) - 1
    zs = z[order]
    at = np.flatnonzero(first)
    nxt = np.minimum(at + GROUND_HELD, len(zs) - 1)
    return (at + GROUND_HELD < len(zs)) & (col[nxt] == col[at]) & (zs[nxt] - zs[at] < gap)


def _mirror_surface(pts: np.ndarray, low: np.ndarray, band_frac: float, inside: np.ndarray, lo: float,
                    hi: float) -> Found:
    """``find_ground``'s third try, for a tree mirrored under its ground (multipath off wet ground or a
    puddle: a share of all its points, crown and trunk, at z -> 2 z_ground - z): each surface through the
    column minima ``low`` (M, 3), then through those of the points in the upper ``1 - GROUND_MIRROR_LOW``
    of ``lo`` to ``hi`` (the mirror stretches the span down about as far as the tree stands above its
    ground, and its minima under a small ground hide it), is cut (``_cut``) with the points under it that
    it mirrors onto the cloud not counted below it (``_mirrored``). Scan 10 and a eucalyptus with 0.2-3 %
    of their points mirrored had no ground (12 of 110 clouds): the first's 16 columns were too few to fit
    a plane to, the second's mirror held 2 % of its points under its ground. Not tried when more than
    ``GROUND_APART`` of the points lie in the lowest third of the span: a mirror reaching half as deep
    as the tree stands tall (``_mirrored``) holds only its own few points there (a tree with no ground
    spent 80 ms here, scan 07)."""
    none = np.zeros(len(pts), bool), None
    h = hi - lo
    if (pts[:, 2] < lo + h / 3).mean() > GROUND_APART:  # a mirror half as deep as the tree: its third, sparse
        return none
    top = lo + GROUND_MIRROR_LOW * h
    upper = pts[(pts[:, 2] >= top) & (pts[:, 2] <= hi)]
    order, first = _columns_low_first(upper[:, :2], upper[:, 2], GROUND_CELL * (hi - top))
    for sample, scale in ((low, h), (upper[order[first]], hi - top)):
        for ground, under in _candidates(pts, sample, band_frac, scale):
            counted = ~_mirrored(pts, under, band_frac * scale / 2)
            if counted.all():
                continue
            cut = _cut(pts, under, band_frac, inside, counted)
            if cut is not None and cut[1]:
                return cut[0], ground
    return none


def _narrow_surface(pts: np.ndarray, body: np.ndarray, band_frac: float, lo: float, hi: float) -> Found:
    """``find_ground``'s last held try, on a narrow cloud (under ``GROUND_NARROW`` columns), or one whose
    first surface is a ground but for the points below it (``_buried``), with many scattered points (``_many_scattered``): ``_held_at`` with each of ``GROUND_HELD_FEW`` points held,
    in columns as wide as ``GROUND_CELL`` of the span, then half that, over the span of the points with
    each of those counts held in columns half as wide, when they lie a column width or more above the
    cloud's floor ``lo`` (``body``: the points of ``pts`` within ``lo`` to ``hi``). A thinned cloud's
    ground has too few points to hold ``GROUND_HELD`` in 20 columns."""
    none = np.zeros(len(pts), bool), None
    cell = GROUND_CELL * (hi - lo)
    order, first = _columns_low_first(body[:, :2], body[:, 2], cell / 2)
    spans = [_held_span(body, order, first, band_frac, lo, hi, k) for k in GROUND_HELD_FEW]
    if all(span is None or span[0] - lo < cell for span in spans) or not _many_scattered(pts):
        return none  # nothing strewn under the held points, or no outliers to hold
    for span in spans:
        if span is None or span[0] - lo < cell:
            continue
        for k in GROUND_HELD_FEW:  # the span of the points with more held, searched with fewer held too
            for wide in (GROUND_CELL, GROUND_CELL / 2):  # the held span's own columns, then half as wide
                found = _held_at(pts, span, band_frac, k, wide)
                if found[1] is not None:
                    return found
    return none


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


def _held_surface(pts: np.ndarray, body: np.ndarray, order: np.ndarray, first: np.ndarray, band_frac: float,
                  lo: float, hi: float) -> tuple[np.ndarray, Ground | None]:
    """``find_ground``'s second try: ``_held_at`` with ``GROUND_HELD`` points held, then with each of
    ``GROUND_HELD_MORE`` whose held points lie a column width or more higher than the last searched
    (outliers so many that they hold each other: 7-20 % of them under scan 10's ground), and only when
    that many stand apart (``_many_scattered``); none when even the last of those reaches the cloud's
    floor (no outliers under it: a tree with no ground and a dense trunk foot). ``body``
    (M, 3): the points of ``pts`` within ``lo`` to ``hi``; ``order``, ``first``: its columns, lowest
    first. No points and None when none finds a ground."""
    none = np.zeros(len(pts), bool), None
    cell = GROUND_CELL * (hi - lo)
    most = _held_span(body, order, first, band_frac, lo, hi, GROUND_HELD_MORE[-1])
    if most is not None and most[0] - lo < cell:  # nothing strewn below the cloud: no other ground to find
        return none
    last, scattered = lo, None
    for k in (GROUND_HELD, *GROUND_HELD_MORE):
        span = most if k == GROUND_HELD_MORE[-1] else _held_span(body, order, first, band_frac, lo, hi, k)
        if span is None or span[0] - last < cell:  # nothing more set aside than the last search did
            continue
        if k != GROUND_HELD:
            scattered = _many_scattered(pts) if scattered is None else scattered
            if not scattered:
                break  # a sparse trunk foot under dense branch layers, not outliers holding each other
        found = _held_at(pts, span, band_frac, k)
        if found[1] is not None:
            return found
        last = span[0]
    return none


def _many_scattered(pts: np.ndarray) -> bool:
    """Whether ``SCATTER_SHARE`` of ``pts`` (N, 3) or more stand apart (``strays.scattered``, read on a
    fixed sample of ``SCATTER_SAMPLE`` of them, their neighbours among all): the deeper held searches
    (``GROUND_HELD_MORE``) are for outliers so many that they hold each other. Without this a tree with no ground, dense flat branch layers and a
    sparsely seen trunk under them had a layer cut as its ground (helper-146's review: 24 of 48 such
    clouds, the root 21-50 % of the height up the trunk; 0 before)."""
    from .strays import SCATTER_SHARE, scattered

    return scattered(pts, SCATTER_SAMPLE) >= SCATTER_SHARE


def _held_span(body: np.ndarray, order: np.ndarray, first: np.ndarray, band_frac: float, lo: float, hi: float,
               k: int) -> tuple[float, float] | None:
    """``body_span`` of the points of ``body`` (M, 3) with ``k`` more of their column within half of
    ``band_frac`` of its height (``lo`` to ``hi``) above them (``held``; ``order``, ``first``: its
    columns, lowest first), or None when they hold fewer than 20 columns."""
    order, first = held(body[:, 2], order, first, band_frac * (hi - lo) / 2, k)
    return body_span(body[order, 2]) if first.sum() >= 20 else None  # the outliers' few held points aside


def _held_at(pts: np.ndarray, span: tuple[float, float], band_frac: float, k: int,
             cell: float = GROUND_CELL) -> Found:
    """``_surface`` through the lowest point of each column of ``pts`` (N, 3) within ``span`` (``lo``,
    ``hi``: ``_held_span``'s) that has ``k`` more of its column just above it (``held``), only such
    points counted below the ground (``_cut``: outliers strewn under it are no trunk under a crown's
    underside); or no points and None. ``cell``: the columns' width, a fraction of the span's height."""
    lo, hi = span
    h = hi - lo
    inside = (pts[:, 2] >= lo) & (pts[:, 2] <= hi)
    body = pts[inside]
    order, first = _columns_low_first(body[:, :2], body[:, 2], cell * h)
    order, first = held(body[:, 2], order, first, band_frac * h / 2, k)
    if first.sum() < 20:
        return np.zeros(len(pts), bool), None
    counted = np.zeros(len(pts), bool)
    counted[np.flatnonzero(inside)[order]] = True
    found, _, _ = _surface(pts, body[order[first]], band_frac, inside, h, counted)
    return found if found[1] is not None else (np.zeros(len(pts), bool), None)


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


def _candidates(pts: np.ndarray, low: np.ndarray, band_frac: float, h: float,
                counted: np.ndarray | None = None) -> Iterator[tuple[Ground, np.ndarray]]:
    """``_surface``'s surfaces to try, in order, each with its heights under ``pts`` (N,): the better
    fitting of plane and curve, the other, then each following the dips of its columns."""
    tol = band_frac * h / 2
    coef = ground_plane(low, tol)
    if coef is None:
        return
    first, second = Ground(coef), None
    gain = GROUND_GAIN * len(low)
    if _fits(low, first, tol) + gain < len(low):  # room for a curve to fit more
        second = ground_curve(low, coef, tol, h)
        if second is not None and _fits(low, second, tol) > _fits(low, first, tol) + gain:
            first, second = second, first
    yield first, first.height(pts[:, :2])
    second = ground_curve(low, coef, tol, h) if second is None else second
    if second is not None:
        yield second, second.height(pts[:, :2])
    for ground in (first, second):
        if ground is None:
            continue
        under = ground.height(pts[:, :2])
        if _below(pts[:, 2] - under < -GROUND_DITCH * h, counted):
            continue  # deeper than any dip is followed: they would stay below it (quick)
        under = under + _dips(pts, under, GROUND_CELL * h, GROUND_DIP * h)
        if not _below(pts[:, 2] - under < -GROUND_DIP * h, counted):
            yield ground, under


def _below(under: np.ndarray, counted: np.ndarray | None) -> bool:
    """Whether more than ``GROUND_BELOW`` of the points (of those ``counted``, (N,) bool, if given) lie
    below a ground (``under``: (N,) bool, each point's)."""
    if counted is None:
        return bool(under.sum() > GROUND_BELOW * len(under))
    return bool((under & counted).sum() > GROUND_BELOW * counted.sum())


def _fits(low: np.ndarray, ground: Ground, tol: float) -> int:
    """How many of the column minima ``low`` (M, 3) lie within ``tol`` of ``ground``."""
    return int((np.abs(low[:, 2] - ground.height(low[:, :2])) < tol).sum())


def _dips(pts: np.ndarray, under: np.ndarray, cell: float, deep: float) -> np.ndarray:
    """(N,) how far the lowest point of each point's ``cell``-wide column of ``pts`` (N, 3) lies below
    the ground heights ``under`` (N,), where that is less than ``deep`` or the column is linked to such
    a one (``_linked``: a ditch or a hollow, the ground follows it), else 0 (a trunk under a crown's
    underside lies deeper)."""
    rel = pts[:, 2] - under
    order, first = _columns_low_first(pts[:, :2], rel, cell)
    low = rel[order[first]]
    follow = (low < 0) & (low > -deep)
    follow |= (low < 0) & _linked(pts[order[first], :2], low, cell, deep)
    dip = np.zeros(len(pts))
    dip[order] = np.where(follow, low, 0.0)[np.cumsum(first) - 1]
    return dip


def _linked(xy: np.ndarray, low: np.ndarray, cell: float, deep: float) -> np.ndarray:
    """(M,) bool: the columns (their points ``xy`` (M, 2) and lowest heights ``low`` (M,) over the ground,
    ``cell`` wide) at most ``GROUND_DITCH`` / ``GROUND_DIP`` times ``deep`` below the ground that a chain
    of neighbouring columns, each at most ``GROUND_WALL`` times ``cell`` deeper than the last, links to a
    column less than ``deep`` below it or above it: the walls of a ditch, not a trunk standing under a
    crown's underside (whose top is no ground to start from)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    cell = max(cell, float(np.ptp(xy, axis=0).max()) / 2 ** 20, 1e-300)
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64)
    wide = int(ij[:, 1].max()) + 3
    key = ij[:, 0] * wide + ij[:, 1] + 1
    order = np.argsort(key)
    near = low > -GROUND_DITCH / GROUND_DIP * deep
    pairs = []
    for step in (wide, 1, wide + 1, wide - 1):  # the neighbours right, up and on both diagonals
        at = np.minimum(np.searchsorted(key[order], key + step), len(key) - 1)
        other = order[at]
        ok = (key[other] == key + step) & near & near[other]
        ok &= np.abs(low - low[other]) <= GROUND_WALL * cell * (np.sqrt(2) if step in (wide + 1, wide - 1) else 1)
        pairs.append(np.c_[np.flatnonzero(ok), other[ok]])
    pairs = np.concatenate(pairs)
    m = len(low)
    _, lab = connected_components(coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m)),
                                  directed=False)
    start = np.zeros(lab.max() + 1, bool)
    start[lab[near & (low > -deep)]] = True
    return near & start[lab]


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
