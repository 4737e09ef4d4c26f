"""Points linked at the trunk base's scale (``LINK`` of the height), for ``trunkbase.find_root`` and
``trunkbase_piece.detached``: the clusters of points linked closer than that (``_link``), and outliers told
from a trunk's foot by how many neighbours they have within it (``_dense_start``: lone points under the
trunk; ``_strewn``: a web of outliers in the base band; ``_lone_most``, ``_dense_enough``). Also the plan
radius both read (``plan_radius``) and the counts they share (``BASE_MIN``, ``BASE_NEIGHBOURS``). Split out
of ``trunkbase`` in session 25.
"""

from __future__ import annotations

import numpy as np

BASE_MIN = 10
"""The base band holds at least this many points (a flat cloud's lowest 3 % holds one or two, whose
spread would read as a trunk's)."""
LINK = 0.02
"""Points of the base band closer than this fraction of the height belong to one cluster."""
BASE_NEIGHBOURS = 4
"""``_dense_start``: a point of a trunk's foot has at least this many others within ``LINK`` of the height."""
LINK_MAX = 4000
"""A base band of more points is clustered on this many of them (``_link``)."""


def plan_radius(q: np.ndarray, percent: float) -> float:
    """The ``percent``-th percentile of the plan-view distances of ``q`` (M, 3) from their median."""
    return float(np.percentile(np.linalg.norm(q[:, :2] - np.median(q[:, :2], axis=0), axis=1), percent))


def _link(base: np.ndarray, r: float) -> np.ndarray:
    """(M,) labels of the connected components of ``base`` (M, 3) with links shorter than ``r``.

    The pairs of a dense band grow with the square of its points (a million-point cloud decomposed
    with ``--points 0`` took 9 GB here, deaf to Ctrl-C), so a band of more than ``LINK_MAX`` points
    is clustered on ``LINK_MAX`` of them drawn with a fixed seed, and every other point takes the
    label of its nearest drawn point within ``r`` (a label of its own beyond)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    drawn = np.arange(len(base))
    if len(base) > LINK_MAX:
        drawn = np.sort(np.random.default_rng(0).choice(len(base), LINK_MAX, replace=False))
    pairs = cKDTree(base[drawn]).query_pairs(r, output_type="ndarray")
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(drawn),) * 2)
    n, lab = connected_components(adj, directed=False)
    if len(drawn) == len(base):
        return lab
    d, j = cKDTree(base[drawn]).query(base, distance_upper_bound=r)
    far = ~np.isfinite(d)
    out = np.where(far, 0, lab[np.minimum(j, len(drawn) - 1)])
    out[far] = n + np.arange(far.sum())
    return out


def _dense_start(pts: np.ndarray, up: np.ndarray, h: float) -> float:
    """The lowest ``up`` (N,) of a point of ``pts`` (N, 3) with ``_lone_most`` others or more (at least
    ``BASE_NEIGHBOURS``) within ``LINK`` of the height ``h`` (x, y and ``up``): outliers strewn under a
    tree with no ground stand alone there (scans 01, 06, 07 and the harmonic apple with 0.5-5 % uniform
    outliers: the root went onto them, up to 25 % of the height low, or the band was refused as too
    wide), a trunk's foot does not. The lowest point when none has."""
    from scipy.spatial import cKDTree

    q = np.c_[pts[:, :2], up]
    tree = cKDTree(q)
    if not _dense_enough(tree, q, LINK * h):
        return float(up.min())
    need = _lone_most(tree, q, LINK * h)
    order = np.argsort(up, kind="stable")
    for at in range(0, len(order), 256):  # the lowest first: the trunk's foot comes soon
        some = order[at:at + 256]
        count = tree.query_ball_point(q[some], LINK * h, return_length=True)
        dense = np.flatnonzero(count > need)  # itself counted
        if len(dense):
            return float(up[some[dense[0]]])
    return float(up.min())


PROBES = 2000
"""``_lone_most`` counts the points round this many places drawn uniformly over the cloud's box."""


def _lone_most(tree, q: np.ndarray, radius: float) -> int:
    """How many others within ``radius`` a point of ``q`` (N, 3) (``tree``: its cKDTree) needs to be no
    outlier: ``BASE_NEIGHBOURS``, or more where outliers are dense, mu + 4 sqrt(mu) + 2 for
    mu the median count round ``PROBES`` places drawn over the box (a tree fills little of it; uniform
    outliers fill it all). A pine 20 tall with a crown 1.2 wide and 5-30 % uniform outliers in a box 20 %
    wider has mu 1-7, and some of them 4-8 others near: the root went onto them, 2-4 under its foot,
    in 52 of 240 draws; scans 01, 06, 07 with up to 5 % outliers in their wider boxes have mu 0."""
    lo, hi = q.min(axis=0), q.max(axis=0)
    at = np.random.default_rng(0).uniform(lo, hi, (PROBES, 3))
    mu = float(np.median(tree.query_ball_point(at, radius, return_length=True)))
    return max(BASE_NEIGHBOURS, int(mu + 4.0 * np.sqrt(mu) + 2.0))


CORE = 16
"""A trunk's foot holds points with more than this many others within ``LINK`` of the height (a typical
point in a cloud ``_dense_enough``): a band's cluster with ``BASE_MIN`` such points is no outliers'
web (``_strewn``)."""


def _strewn(pts: np.ndarray, up: np.ndarray, h: float, cluster: np.ndarray) -> bool:
    """Whether the base band's largest cluster (indices ``cluster`` into ``pts`` (N, 3)) is outliers linked
    into a web, not a trunk's foot: in a cloud ``_dense_enough`` where outliers are dense (``_lone_most``
    above ``BASE_NEIGHBOURS``), fewer than ``BASE_MIN`` of its points (of up to 2,000 drawn) have more
    others than an outlier within ``LINK`` of the height ``h`` (a pine 20 tall, 1.2 wide, with 15-30 %
    uniform outliers and a ground found on their floor: the root went 2-3.4 under its foot). Points with
    ``CORE`` others are looked for first, near the band only: a trunk's foot has them."""
    from scipy.spatial import cKDTree

    r = LINK * h
    if len(cluster) > 2000:
        cluster = np.random.default_rng(0).choice(cluster, 2000, replace=False)
    near = np.flatnonzero((up >= up[cluster].min() - r) & (up <= up[cluster].max() + r))
    q = np.c_[pts[:, :2], up]
    count = cKDTree(q[near]).query_ball_point(q[cluster], r, return_length=True)
    if (count > CORE).sum() >= BASE_MIN:
        return False
    tree = cKDTree(q)
    if not _dense_enough(tree, q, r) or (need := _lone_most(tree, q, r)) <= BASE_NEIGHBOURS:
        return False
    return bool((count > need).sum() < BASE_MIN)


SPARSE_SHARE = 0.25
"""``_dense_start`` tells lone points from a trunk's foot only where a typical point has at least
``BASE_NEIGHBOURS`` / this many neighbours within ``LINK`` of the height."""


def _dense_enough(tree, q: np.ndarray, radius: float) -> bool:
    """Whether the typical point of ``q`` (the median of up to 500) has ``BASE_NEIGHBOURS`` /
    ``SPARSE_SHARE`` neighbours within ``radius`` (``tree``: its cKDTree). In a sparser cloud a trunk's
    foot is as lonely as an outlier: in 600 points of the toy tree the band started 20 % of the height up
    the trunk, and asked for fewer neighbours, 120 points of scan 01 were refused ("no trunk base")."""
    pick = np.random.default_rng(0).choice(len(q), min(len(q), 500), replace=False)
    typical = float(np.median(tree.query_ball_point(q[pick], radius, return_length=True))) - 1.0
    return typical >= BASE_NEIGHBOURS / SPARSE_SHARE
