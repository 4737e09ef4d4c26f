"""A piece apart under the tree (``preprocess._rooted`` reads both): ``detached`` finds the small piece
holding the root when it lies apart under the tree (a clump, strays), and ``under`` tells whether such a
piece is the trunk's own foot seen apart by a gap in the scan (under the trunk's axis, ``_axis_at``; not a
clump that fills a disc in plan and crowds its centre, ``_filled``, ``_peaked``, unless it is as wide and
dense as the trunk, ``_like_trunk``). Split out of ``trunkbase`` (which re-exports both) in session 25.
"""

from __future__ import annotations

import numpy as np

from .trunkbase_links import BASE_MIN, BASE_NEIGHBOURS, LINK, _link, plan_radius

APART_SPAN = 0.2
"""``detached``: the piece holding the root is apart from the tree when it ends (its highest point) more
than ``LINK`` under this fraction of the height above the root's foot, ..."""
APART_SHARE = 0.05
"""... and holds under this share of the points (a clump of 1-3 % of the points 5-20 % of the height
under scans 01, 06 and 07 with no ground was their root, helper-149)."""


def detached(pts: np.ndarray, up: np.ndarray, root: np.ndarray) -> np.ndarray:
    """(N,) bool: the piece of ``pts`` (N, 3) holding the ``root`` (3,) (its points linked closer than
    ``LINK`` of the height, up to ``APART_SPAN`` of it above the root's foot, in ``up`` (N,)) when it
    lies apart under the tree: ending lower than that and holding under ``APART_SHARE`` of the points,
    and ``BASE_MIN`` or more (9 points of scan 06's foot 0.5 under the rest, half the scan occluded, are
    no clump: they lie 0.22 beside the trunk above and are its foot). All False otherwise (the tree's
    own foot: the piece runs on up the trunk)."""
    h = float(np.ptp(pts[:, 2]))
    out = np.zeros(len(pts), bool)
    foot = int(np.argmin(np.linalg.norm(pts - root, axis=1)))
    window = np.flatnonzero(up <= up[foot] + APART_SPAN * h)
    q = np.c_[pts[window, :2], up[window]]
    if _climbs(q, int(np.searchsorted(window, foot)), up[foot] + (APART_SPAN - LINK) * h, LINK * h):
        return out
    lab = _link(q, LINK * h)
    inside = lab == lab[np.searchsorted(window, foot)]
    piece = window[inside]
    if up[piece].max() < up[foot] + (APART_SPAN - LINK) * h and BASE_MIN <= len(piece) < APART_SHARE * len(pts):
        out[piece] = True
        out[window[_scatter(q, lab, inside, LINK * h)]] = True
        if not _gapped(np.c_[pts[:, :2], up], out, (1.0 if _filled(pts[out, :2]) else APART_GAP) * LINK * h):
            out[:] = False
    return out


APART_GAP = 1.5
"""``detached``: the piece's nearest point to the rest lies farther than this many ``LINK``, and than
``APART_SPACING`` times the spacing of the piece's own points: a real gap. A sparse trunk's points lie
just over ``LINK`` apart, so its own foot came out as a piece, and the root went up the trunk by up to
11 % of the height (15 of 600 synthetic clouds of 1,000-6,000 points with no ground; all 7 with ground
where it fired: helper-161's review). A piece that fills a disc in plan (``_filled``: a clump; a sparse
trunk's foot is a ring) needs a gap of ``LINK`` only: a clump 5 % of the height under a scan's foot lay
1.3-1.5 ``LINK`` from it and stayed the root (helper-170)."""
APART_SPACING = 5.0
"""See ``APART_GAP``: the gap is wider than this many times the piece's own spacing."""


def _gapped(q: np.ndarray, piece: np.ndarray, least: float) -> bool:
    """Whether the points of ``q`` (N, 3) in ``piece`` (N,) bool lie farther than ``least`` from the
    others, and than ``APART_SPACING`` times the median distance between the piece's own neighbours."""
    from scipy.spatial import cKDTree

    gap = float(cKDTree(q[~piece]).query(q[piece])[0].min())
    spacing = float(np.median(cKDTree(q[piece]).query(q[piece], k=2)[0][:, 1]))
    return gap > max(least, APART_SPACING * spacing)


def _scatter(q: np.ndarray, lab: np.ndarray, inside: np.ndarray, r: float) -> np.ndarray:
    """(M,) bool: the points of ``q`` (M, 3) round the piece (``inside``), in groups (``lab``) of up to
    ``BASE_NEIGHBOURS`` points lower than its top and within ``2 r`` of it: its scattered edge, which goes
    with it (a clump's lone points left behind were the lowest of the rest, and the root found again
    took its height from them: 1.55 under a 20-tall tree's foot seen apart, helper-157)."""
    from scipy.spatial import cKDTree

    small = (np.bincount(lab)[lab] <= BASE_NEIGHBOURS) & ~inside & (q[:, 2] < q[inside, 2].max())
    near = np.zeros(len(q), bool)
    if small.any():
        d, _ = cKDTree(q[inside]).query(q[small], distance_upper_bound=2 * r)
        near[np.flatnonzero(small)[np.isfinite(d)]] = True
    return near


def _climbs(q: np.ndarray, at: int, top: float, r: float) -> bool:
    """Whether a chain of links shorter than ``r`` leads from point ``at`` of ``q`` (M, 3) up to ``top``
    (third column), each step to the highest point within ``r``: a trunk's foot does in a few steps, so
    ``detached`` need not cluster the window (its clustering cost scans 07 and 10 +35-54 % of ``prepare``)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(q)
    for _ in range(1000):
        if q[at, 2] >= top:
            return True
        near = tree.query_ball_point(q[at], r)
        step = near[int(np.argmax(q[near, 2]))]
        if q[step, 2] <= q[at, 2]:
            return False
        at = step
    return False


AXIS_SLAB = 0.1
"""``under`` fits the trunk's axis on the points up to this fraction of the height above the root found
without the piece, within as much of it in plan."""


def under(piece: np.ndarray, rest: np.ndarray, root: np.ndarray, h: float) -> bool:
    """Whether ``piece`` (M, 3), apart under the tree (``detached``), stands under the trunk whose foot
    ``root`` (3,) was found on ``rest`` (K, 3) without it: its plan centre within its 90th-percentile plan
    radius (at least ``LINK`` of the height ``h``) of the root's, or of the trunk's axis carried down to
    the piece's height (``_axis_at``). Then it is that trunk's foot, seen apart from the rest by a gap in
    the scan (undergrowth hid a pine's trunk from 0.5 to 2.7 m on 19 m, helper-96's review): it keeps
    the root. Measured at the root alone, the feet of trees leaning 10-30 degrees with their trunk unseen
    for 2-15 % of the height above the foot were left out, 216 of 480 (helper-156's review); measured on
    the axis alone, a sparse trunk's under branch layers reaching into the slab, 5 of 96 (helper-153's
    whorled trees: the line pulled 1.1 off the trunk). A piece that fills a disc in plan (``_filled``,
    seen along the axis's slope) is no foot but a clump, wherever it stands: clumps of 1-3 % of the points
    centred under scans 01, 06, 07 were the root, 7.5-23 % of the height low (27 of 90, helper-170) -
    when it also crowds its centre (``_peaked``) and differs from the trunk above (``_like_trunk``): a foot
    noisy for its width, filled by photogrammetry or holding several stems fills a disc too, and was left
    out, the root up at the gap's top (73 of 960 clouds, helper-172)."""
    tol = max(plan_radius(piece, 90), LINK * h)
    centre = np.median(piece[:, :2], axis=0)
    z = float(np.median(piece[:, 2]))
    axis = _axis_at(rest, root, h, z)
    if np.linalg.norm(centre - root[:2]) > tol and np.linalg.norm(centre - axis) > tol:
        return False
    lean = (_axis_at(rest, root, h, z + AXIS_SLAB * h) - axis) / (AXIS_SLAB * h)
    xy = piece[:, :2] - np.outer(piece[:, 2] - z, lean)
    return not (_filled(xy) and _peaked(xy) and not _like_trunk(piece, xy, rest, root, h))


PEAKED = 1.2
"""``_peaked``: a clump's points crowd its centre: their plan density within ``PEAK_CORE`` of their median
distance from the fitted circle's centre is this many times or more that between 0.8 and 1.2 of it (a
Gaussian blob: 1.8; helper-170's clumps under scans 01, 06, 07 and under leaning trunks, 177 pieces of
112-348 points: all over 1.2). A foot filled in plan is no denser at its centre than round it: interior
points of a photogrammetric foot fill a disc evenly (1.0), a noisy ring is hollower (helper-172)."""
PEAK_CORE = 0.6
"""``_peaked``'s core, as a fraction of the median distance (wider than ``HOLLOW_CORE``: a clump of 112
points held 12 within 0.4 of it, too few to weigh: 1.29 there)."""
TRUNK_LIKE = 1.3
"""``_like_trunk``: a piece whose plan width and points per unit height are both within this factor of the
trunk's over ``AXIS_SLAB`` above the root is that trunk's foot, however it fills (a sapling 2-6 cm in
radius scanned with 1-5 cm noise is a disc with a peaked centre: 0.79-1.09 and 0.89-1.11; helper-170's
clumps differ by 1.66-2.04 in one of them, helper-172)."""


def _peaked(xy: np.ndarray) -> bool:
    """Whether the plan positions ``xy`` (M, 2) crowd their centre (``PEAKED``): a blob, not a disc or ring."""
    d = _from_circle(xy)
    m = float(np.median(d))
    core = (d < PEAK_CORE * m).sum() / PEAK_CORE ** 2
    ring = ((d > 0.8 * m) & (d < 1.2 * m)).sum() / (1.2 ** 2 - 0.8 ** 2)
    return bool(core >= PEAKED * max(ring, 1.0))


def _like_trunk(piece: np.ndarray, xy: np.ndarray, rest: np.ndarray, root: np.ndarray, h: float) -> bool:
    """Whether ``piece`` (M, 3) (``xy`` (M, 2): its plan along the trunk's lean) is as wide and as dense per
    unit height as the trunk rising from ``root`` (3,) in ``rest`` (K, 3) (``_axis_at``'s points, within
    ``TRUNK_LIKE``): that trunk's foot."""
    near = _trunk_slab(rest, root, h)
    if near is None:
        return False
    fit = np.array([np.polyval(line, near[:, 2]) for line in _axis_line(near)]).T
    wide = plan_radius(np.c_[xy, piece[:, 2]], 90) / max(float(np.percentile(np.linalg.norm(near[:, :2] - fit, axis=1), 90)), 1e-12)
    lo, hi = np.percentile(piece[:, 2], [10, 90])
    dense = 0.8 * len(piece) / max(float(hi - lo), 1e-12) / (len(near) / float(np.ptp(near[:, 2])))
    return bool(max(wide, 1 / max(wide, 1e-12), dense, 1 / max(dense, 1e-12)) <= TRUNK_LIKE)


HOLLOW_CORE = 0.4
"""``_filled``: the core of a piece in plan, as a fraction of its points' median distance from its circle's
centre, ..."""
FILLED_SHARE = 0.04
"""... in which a trunk's foot holds under this share of its points (a ring of bark: none; the buttressed
scan 07's foot cut off by a gap: up to 1.4 %), and a clump more (a Gaussian blob: 10.5 %; clumps of 1-3 %
of the points under scans 01, 06, 07: 6.6 % or more)."""


def _filled(xy: np.ndarray) -> bool:
    """Whether the plan positions ``xy`` (M, 2) of a piece fill a disc rather than lie on a ring: ``FILLED_SHARE``
    of them or more lie within ``HOLLOW_CORE`` of the median distance from the centre of the circle fitted
    to them (an algebraic fit: a half-seen foot's arc finds its centre)."""
    d = _from_circle(xy)
    return bool((d < HOLLOW_CORE * np.median(d)).mean() >= FILLED_SHARE)


def _from_circle(xy: np.ndarray) -> np.ndarray:
    """(M,) distances of the plan positions ``xy`` (M, 2) from the centre of the circle fitted to them (an
    algebraic fit: a half-seen foot's arc finds its centre): ``_filled``'s and ``_peaked``'s reading."""
    a = np.c_[2.0 * xy, np.ones(len(xy))]
    centre = np.linalg.lstsq(a, (xy ** 2).sum(axis=1), rcond=None)[0][:2]
    return np.linalg.norm(xy - centre, axis=1)


def _axis_at(rest: np.ndarray, root: np.ndarray, h: float, z: float) -> np.ndarray:
    """(2,) plan position at height ``z`` of the trunk rising from ``root`` (3,) in ``rest`` (K, 3): a
    straight line x(z), y(z) fitted on its points within ``AXIS_SLAB`` of the height ``h`` above and
    beside the root, carried down; the root's own position when they are under ``BASE_MIN`` or span
    under ``LINK`` of the height."""
    near = _trunk_slab(rest, root, h)
    if near is None:
        return root[:2]
    return np.array([np.polyval(line, z) for line in _axis_line(near)])


def _trunk_slab(rest: np.ndarray, root: np.ndarray, h: float) -> np.ndarray | None:
    """The points of ``rest`` (K, 3) within ``AXIS_SLAB`` of the height ``h`` above and beside ``root`` (3,):
    the trunk's foot that ``_axis_at`` and ``_like_trunk`` read; None when under ``BASE_MIN`` of them or
    spanning under ``LINK`` of the height."""
    near = rest[(rest[:, 2] >= root[2]) & (rest[:, 2] <= root[2] + AXIS_SLAB * h)
                & (np.linalg.norm(rest[:, :2] - root[:2], axis=1) < AXIS_SLAB * h)]
    return None if len(near) < BASE_MIN or np.ptp(near[:, 2]) <= LINK * h else near


def _axis_line(near: np.ndarray) -> list[np.ndarray]:
    """The straight lines x(z) and y(z) (polynomial coefficients) fitted on the points ``near`` (K, 3)."""
    return [np.polyfit(near[:, 2], near[:, i], 1) for i in (0, 1)]
