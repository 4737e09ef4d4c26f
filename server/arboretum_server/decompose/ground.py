"""Ground under a scanned tree (VRTree Appendix A: "remove the ground when present"): ``find_ground`` cuts a
plane, or a gently curved surface, with the dips of a ditch, grass, shrubs round the trunk and strays
below it, and refuses a crown's underside or a drooping crown. Split out of ``preprocess`` (session 19),
which calls it; docs/decomposition.md, "Ground", has the rules and what was measured.

Here: the search and its tries in turn: among the points not set apart under the rest (``_apart_below``),
the column minima (``_search``), then the columns' held points when outliers lie under or among them
(``_held_surface``, ``_on_strays``, ``_left_in_band``), fewer held on a narrow cloud or a sparse ground
(``_narrow_surface``), a tree mirrored under its ground (``_mirror_surface``). The surfaces are
``ground_surface``'s (``Ground``, ``body_span`` and ``held`` too), whether one is the ground and what it cuts
``ground_cut``'s (split in three in session 25).
"""

from __future__ import annotations

import numpy as np

from .ground_cut import _buried, _cut, _mirrored, _surface, _trunk_under
from .ground_surface import (
    GROUND_CELL,
    GROUND_DIP,
    GROUND_HELD,
    Found,
    Ground,
    _candidates,
    _columns_low_first,
    body_span,
    held,
)

__all__ = ["Found", "Ground", "body_span", "find_ground"]

GROUND_HELD_MORE = (6, 12, 24)
"""``held``'s counts tried in turn after ``GROUND_HELD``: 10-20 % uniform outliers held each other 3 deep
down to their box's floor under scan 10's ground, which was missed in 9-20 of 20 draws (the root 4-24 %
of the height under it)."""
SCATTER_SAMPLE = 5_000
"""``_many_scattered`` reads the share of scattered points on at most this many of them (their
neighbours found among all the points)."""
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
GROUND_MIRROR_LOW = 0.4
"""``_mirror_surface`` searches again among the points above this fraction of the span (the mirror's
half of it set aside)."""


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
