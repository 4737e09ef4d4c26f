"""Stray points: what stands apart from the tree (scanner noise, a bird, a mixed-pixel ghost) and would
otherwise set its trunk base or its height, left out after downsampling (``preprocess.prepare``).

Two kinds, both measured against a tenth of the cloud's height (``STRAY_APART``):

- *lone points*: fewer than ``STRAY_NEIGHBOURS`` other points within that distance;
- *small groups*: pieces of the cloud, cut wherever it has a gap of about that distance, holding under
  ``STRAY_GROUP`` of the points each and lying wholly below or wholly above one piece holding
  ``TREE_SHARE`` of them or more (the tree), farther from it than ``STRAY_GROUP_GAP`` such distances.
  A cluster of 60 points 10 m under scan 07 (71,000 points) was its trunk base before. Pieces level with the tree are kept: they are wood behind a gap in the
  scan (a missing sector cuts limb ends off) more often than noise, and set neither base nor height.

A sparse cloud (more than 1 % lone points, or no piece holding most of the points) has no strays.
"""

from __future__ import annotations

from itertools import product

import numpy as np

STRAY_APART = 0.1
"""A point is a stray when its ``STRAY_NEIGHBOURS``-th nearest neighbour lies farther than this fraction
of the cloud's height (0.1-99.9 percentile of z), and than ``STRAY_SPACING`` times the median such
distance (sparse photo clouds): one stray point 10 m under a 24.5 m tree became its trunk base."""
STRAY_NEIGHBOURS = 4
"""Lone points: up to this many together count as strays one by one."""
STRAY_SPACING = 10.0
"""How many times the cloud's median neighbour distance a stray must stand apart, at least."""
STRAY_EXACT = 50_000
"""Up to this many points ``strays`` looks up every point's neighbours (and applies ``STRAY_SPACING``)."""
STRAY_GROUP = 0.01
"""A piece of the cloud apart from the tree holding fewer than this share of the points is a stray group
(a second tree holds more, and is the several-trees check's business)."""
STRAY_GROUP_GAP = 2.0
"""... and lying more than this many ``STRAY_APART`` distances (a fifth of the height) from the tree: a
trunk's foot seen under a 2.2 m band the scan missed, on a 19 m tree, is no stray (helper-96's review)."""
TREE_SHARE = 0.9
"""Stray groups are only looked for when one piece holds at least this share of the points."""
SCATTER_FAR = 5.0
"""``scattered``: a point stands apart when its ``STRAY_NEIGHBOURS``-th nearest neighbour lies farther
than this many times the cloud's median such distance."""
SCATTER_SPAN = 0.3
"""``scattered``: the middle half of the points standing apart spans at least this share of the height
(uniform outliers: about half; a sparse ground round the tree: 0.0)."""
SCATTER_SHARE = 0.03
"""A refused trunk base names the scattered points as the cause when at least this share of the points
stands apart (``scattered``, on ``prepare``'s thinned points: the four real scans 0.0-0.5 %; with 5 and
10 % uniform outliers 4.5-5.0 and 8.4-9.3 %; on the raw clouds 5.2-6.7 and 10.0 %, helper-146). The
deeper held ground searches ask for it too (``ground._many_scattered``)."""


def strays(pts: np.ndarray) -> np.ndarray:
    """(N,) bool: the points of ``pts`` (N, 3) standing apart, lone or in small groups (module doc).

    Up to ``STRAY_EXACT`` points, every point's neighbours are looked up (a sparse cloud's spacing sets a
    floor on the distance). Beyond, the distance is the height's share alone (such clouds are dense) and
    only points in sparse cells are looked at: 1M points in about 0.3 s instead of 1.5 s."""
    from scipy.spatial import cKDTree

    k = STRAY_NEIGHBOURS + 1
    if len(pts) <= 10 * k:
        return np.zeros(len(pts), bool)
    lo, hi = np.percentile(pts[:, 2], [0.1, 99.9])
    far = STRAY_APART * float(hi - lo)
    if len(pts) <= STRAY_EXACT:
        d, _ = cKDTree(pts).query(pts, k)
        far = max(far, STRAY_SPACING * float(np.median(d[:, -1])))
        lone = d[:, -1] > far
    else:
        lone = _apart(pts, far, k)
    if lone.sum() > 0.01 * len(pts):  # a sparse cloud, not strays
        return np.zeros(len(pts), bool)
    return lone | groups(pts, far)


def groups(pts: np.ndarray, far: float) -> np.ndarray:
    """(N,) bool: points of ``pts`` (N, 3) in small pieces apart from the tree, below or above it (module doc)."""
    out = np.zeros(len(pts), bool)
    if far <= 0 or not np.isfinite(far) or (cut := _pieces(pts, far)) is None:
        return out
    of, size = cut
    tree = int(size.argmax())
    if size[tree] < TREE_SHARE * len(pts):
        return out
    low = np.full(len(size), np.inf)
    high = np.full(len(size), -np.inf)
    np.minimum.at(low, of, pts[:, 2])
    np.maximum.at(high, of, pts[:, 2])
    # beside the tree a piece is wood behind a gap in the scan (a missing sector cuts limbs off), and sets
    # neither the trunk base nor the height
    outside = (high < low[tree]) | (low > high[tree])
    cand = np.flatnonzero((size < STRAY_GROUP * len(pts)) & outside)
    if not len(cand):
        return out
    # a piece just under the tree is its trunk's foot below a band the scan missed (undergrowth): only a
    # piece ``STRAY_GROUP_GAP`` x far from the tree is noise
    from scipy.spatial import cKDTree

    member = np.isin(of, cand)
    gap = cKDTree(pts[of == tree]).query(pts[member])[0]
    nearest = np.full(len(size), np.inf)
    np.minimum.at(nearest, of[member], gap)
    return (np.isin(np.arange(len(size)), cand) & (nearest > STRAY_GROUP_GAP * far))[of]


def _pieces(pts: np.ndarray, far: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(piece of each point (N,), points per piece): the connected sets of occupied cells of side ``far``
    / 2 (26 neighbours): points closer than ``far`` / 2 always share a piece, points farther than ``far`` x
    sqrt(3) apart never link. When the cells' span is too wide for one 64-bit key (a stray 10^6 heights
    away), ``_packed`` closes the gaps; None when even that does not fit (never for a tree)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    c = np.floor((pts - pts.min(axis=0)) / (far / 2.0)).astype(np.int64) + 1  # from 1: cell 0 is a neighbour
    dims = c.max(axis=0) + 2
    if float(np.prod(dims.astype(np.float64))) > 2.0 ** 62:  # a stray very far away: close the gaps
        c = np.stack([_packed(c[:, a]) for a in range(3)], axis=1)
        dims = c.max(axis=0) + 2
        if float(np.prod(dims.astype(np.float64))) > 2.0 ** 62:
            return None
    key = (c[:, 0] * dims[1] + c[:, 1]) * dims[2] + c[:, 2]
    cells, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    rows, nbrs = [], []
    for dx, dy, dz in product((-1, 0, 1), repeat=3):
        if (dx, dy, dz) <= (0, 0, 0):  # each pair once: the 13 offsets after (0, 0, 0)
            continue
        want = cells + (dx * dims[1] + dy) * dims[2] + dz
        j = np.minimum(np.searchsorted(cells, want), len(cells) - 1)
        hit = cells[j] == want
        rows.append(np.flatnonzero(hit))
        nbrs.append(j[hit])
    r, q = np.concatenate(rows), np.concatenate(nbrs)
    _, piece = connected_components(coo_matrix((np.ones(len(r)), (r, q)), shape=(len(cells), len(cells))),
                                    directed=False)
    return piece[inverse.reshape(-1)], np.bincount(piece, weights=count)


def _packed(cells: np.ndarray) -> np.ndarray:
    """Cell coordinates (N,) along one axis renumbered from 1 with every gap of two cells or more made
    two: neighbours stay neighbours, and the span is at most twice the number of occupied cells."""
    u, inv = np.unique(cells, return_inverse=True)
    return np.r_[1, 1 + np.cumsum(np.minimum(np.diff(u), 2))][inv.reshape(-1)]


def _apart(pts: np.ndarray, far: float, k: int) -> np.ndarray:
    """(N,) bool: points of ``pts`` (N, 3) with fewer than ``k`` points (themselves included) within ``far``.

    Cells of side far / sqrt(3) hold points all within ``far`` of each other, so only points in cells of
    fewer than ``k`` can qualify; they are counted against the points of the cells up to two away."""
    from scipy.spatial import cKDTree

    if far <= 0:
        return np.zeros(len(pts), bool)
    cells = np.floor(np.ptp(pts, axis=0) / (far / np.sqrt(3.0))) + 5
    if float(np.prod(cells)) > 2.0 ** 62:  # a cloud far wider than tall: no cell key fits, look up all
        return cKDTree(pts).query(pts, k)[0][:, -1] > far
    ijk = np.floor((pts - pts.min(axis=0)) / (far / np.sqrt(3.0))).astype(np.int64) + 2
    dims = ijk.max(axis=0) + 3
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    cand = np.flatnonzero(count[inverse] < k)
    out = np.zeros(len(pts), bool)
    if not len(cand):
        return out
    step = np.arange(-2, 3)
    offsets = ((step[:, None, None] * dims[1] + step[None, :, None]) * dims[2] + step[None, None, :]).ravel()
    near = np.isin(key, np.unique(key[cand][:, None] + offsets[None, :]))
    counts = cKDTree(pts[near]).query_ball_point(pts[cand], far, return_length=True)
    out[cand] = counts < k
    return out


def scattered(pts: np.ndarray, sample: int | None = None) -> float:
    """The share of ``pts`` (N, 3) whose ``STRAY_NEIGHBOURS``-th nearest neighbour lies farther than
    ``SCATTER_FAR`` times the median such distance: outliers strewn round a tree (uniform ones: about
    their share of the points), which the stray rule keeps when they are many or near each other. 0 when
    the middle half of those points spans less than ``SCATTER_SPAN`` of the height: a sparse ground or
    crown, not points strewn over the whole cloud. ``sample``: read it on at most this many points (a
    fixed draw), their neighbours still found among all the points: a thinned cloud reads too few (scan
    10 with 30-40 % outliers 0.0-5.6 % on 5,000 points of it, helper-147's review)."""
    from scipy.spatial import cKDTree

    if len(pts) <= 10 * (STRAY_NEIGHBOURS + 1):
        return 0.0
    q = pts
    if sample is not None and len(pts) > sample:
        q = pts[np.random.default_rng(0).choice(len(pts), sample, replace=False)]
    d = cKDTree(pts).query(q, STRAY_NEIGHBOURS + 1)[0][:, -1]
    apart = d > SCATTER_FAR * np.median(d)
    if apart.sum() < 4 or np.subtract(*np.percentile(q[apart, 2], [75, 25])) < SCATTER_SPAN * np.ptp(pts[:, 2]):
        return 0.0
    return float(apart.mean())
