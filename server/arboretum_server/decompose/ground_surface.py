"""The ground's surfaces, for ``ground.find_ground``: the span of z with far strays set apart
(``body_span``), each column's lowest point (``_columns_low_first``; ``held``: its lowest point with a few
more of its column just above it), the plane and the curved surface fitted through those minima
(``ground_plane``, ``ground_curve``: a ``Ground``), and the surfaces tried in turn, each once more following
the dips of its columns (``_candidates``; ``_dips``, ``_linked``: a ditch, a hollow). Whether a surface is the
ground is ``ground_cut``'s. Split out of ``ground`` in session 25; docs/decomposition.md, "Ground", has the
rules and what was measured.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

GROUND_CELL = 0.02
"""Ground search: the lowest point of each xy column this wide (fraction of the height) samples it."""
GROUND_TILT = 0.5
"""Steepest ground slope searched (rise over run: 27 degrees)."""
GROUND_TRIES = 200
"""RANSAC triples tried for the ground plane."""
GROUND_SAMPLE = 5000
"""RANSAC scores a plane on at most this many column minima (a wide scan has tens of thousands)."""
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
GROUND_DITCH = 0.1
"""``_dips`` follows a column deeper than ``GROUND_DIP`` down to this fraction of the height below the
ground when a chain of columns, each at most ``GROUND_WALL`` deeper than the last, leads to it from a
shallow one (a ditch 4 % deep and wide, or 8 % deep, was refused with "no trunk base")."""
GROUND_WALL = 1.0
"""Steepest rise over run between neighbouring columns that ``_dips`` follows down (45 degrees)."""
GROUND_GAIN = 0.05
"""A curved ground is tried before the plane when it fits this share of the column minima more."""
GROUND_BEND = 0.15
"""A curved ground rises or falls at most this fraction of the height from its plane part."""


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
