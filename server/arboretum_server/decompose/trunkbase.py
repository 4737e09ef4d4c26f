"""The trunk base (the root) of a cloud, and the checks that it holds one standing tree (ours).

``find_root`` clusters the lowest ``BASE_BAND`` of the height and puts the root on the largest
cluster that is a trunk. Clusters that hang from the crown (a weeping branch's leaves: ``STANDING``,
``_no_column``) or lie on the ground (a crown bent down to it: ``_trunks_under_fallen_crown``) are
no trunks; separate trunks are refused, in the band and, when the ground cut reaches over it, just
above the cut (``_above_cut``: another tree's foot cut with the ground). A second tree standing higher
than the band is ``columns.trunk_columns``' job.
"""

from __future__ import annotations

import numpy as np

from arboretum_library.errors import InputError

BASE_BAND = 0.03
"""Height band (fraction of the tree height) whose points locate the trunk base."""
BASE_MIN = 10
"""The base band holds at least this many points (a flat cloud's lowest 3 % holds one or two, whose
spread would read as a trunk's)."""
GAPPY = 0.25
"""A slab of a trunk's column holds at least this share of its fullest slab (``_no_column``)."""
MAX_BASE_SPREAD = 0.12
"""Largest 90th-percentile plan radius of the base band's largest cluster (fraction of height) that still
is one trunk base: a base about a quarter of the height across."""
STANDING = 0.01
"""A big cluster of the base band whose lowest point lies more than this fraction of the height above the
lowest cluster's, and that holds fewer points per metre of height than ``HANGING_SHARE`` of the largest
cluster's, hangs from the crown (a weeping branch's tips or leaves reaching into the band): it is no
second tree."""
LINK = 0.02
"""Points of the base band closer than this fraction of the height belong to one cluster."""
BASE_NEIGHBOURS = 4
"""``_dense_start``: a point of a trunk's foot has at least this many others within ``LINK`` of the height."""
FLOOR_UNDER = 0.05
"""When the base band starts more than this fraction of the height above the ground found, that ground is
the floor of outliers strewn under the trees, not theirs, and its tilt is noise: ``find_root``'s
several-trees check is made on the heights as given too (two pines 6 apart, no ground, 5 % uniform
outliers: a floor tilted 0.22 put their feet 2.3 and 3.6 over it, in no one band; helper-171)."""
LINK_MAX = 4000
"""A base band of more points is clustered on this many of them (``_link``)."""
HANGING_SHARE = 0.5
"""See ``STANDING``. Points are counted per metre between a cluster's lowest point and the band's top, so
a second trunk up a slope, whose lower part the band cuts off, still counts as a tree (and a stray point
under the trunk, which lowers the trunk's count, makes no other cluster hang)."""


def plan_radius(q: np.ndarray, percent: float) -> float:
    """The ``percent``-th percentile of the plan-view distances of ``q`` (M, 3) from their median."""
    return float(np.percentile(np.linalg.norm(q[:, :2] - np.median(q[:, :2], axis=0), axis=1), percent))


def find_root(pts: np.ndarray, up: np.ndarray | None = None, cut: float | None = None) -> np.ndarray:
    """(3,) trunk base of ``pts`` (N, 3): centre of the largest cluster in the lowest band, at its lowest z.

    The band is the lowest ``BASE_BAND`` of the height, measured in ``up`` (N,), each point's height
    above the ground, when one was found (a second tree up the slope stands in it too), else from the
    lowest point. When the band holds no big cluster, or its largest is outliers linked into a web
    (``_strewn``), and no point with more neighbours within ``LINK`` of the height than an outlier has
    (``_lone_most``), it starts at the lowest such point instead (``_dense_start``: lone points under the
    trunk; a flat patch there has the several-trees check run above it, ``_above_cut``).
    InputError when the band holds several well-separated trunks (clusters hanging from the crown aside:
    ``STANDING``, ``_no_column``), or when its largest cluster spreads too wide to be one trunk base.
    A second tree standing higher than the band is not refused here: see ``columns.trunk_columns``.
    ``cut``: the height in ``up`` up to which the ground was cut away (``ground.find_ground``), or None.
    When the band starts lower, the several-trees check is made on a band from there too (``_above_cut``):
    the ground cut keeps only the trunk of the narrowest slice, so another tree's foot went with the
    ground and stood above the band (two pines among 2-15 % uniform outliers, the cut risen 0.45-2.4 m
    on 20 m in 16 of them: taken as one tree in 23 of 40 clouds, helper-146; 6 after this check, their ground
    tilted or found on the outliers' floor; 0 since session 24). When the band starts more than ``FLOOR_UNDER``
    of the height above the ground, that ground is the outliers' floor, whose tilt set the feet apart in
    ``up``: the check is made on the heights as given too (``_above_cut`` from ``_dense_start`` in z).
    Only to refuse: the root stays.
    """
    z = pts[:, 2]
    h = np.ptp(z)
    up = z if up is None else up
    start = float(up.min())
    band, lab, big = _band(pts, up, h, start)
    if (not len(big) or _strewn(pts, up, h, band[lab == big[0]])) \
            and (dense := _dense_start(pts, up, h)) > start + BASE_BAND * h:  # lone points under it
        start = dense
        band, lab, big = _band(pts, up, h, start)
        if len(big) and _flat(np.c_[pts[band, :2], up[band]][lab == big[0]], h):  # ground among outliers,
            _above_cut(pts, up, h, start)  # perhaps two trees' patches joined: look above it
    if cut is not None and cut > start:
        _above_cut(pts, up, h, cut)
    if up is not z and start > FLOOR_UNDER * h:  # the ground found lies far under the trees: its tilt is
        _above_cut(pts, z, h, _dense_start(pts, z, h))  # the outliers' floor's, no ground's: check level too
    trunk = pts[band[lab == big[0]]] if len(big) else pts[band]
    centre = np.median(trunk[:, :2], axis=0)
    r90 = plan_radius(trunk, 90)
    if r90 > MAX_BASE_SPREAD * h:
        raise InputError(
            f"point cloud: no trunk base found (the lowest {BASE_BAND:.0%} of the cloud spreads "
            f"{r90:.3g} wide for a height of {h:.3g}); crop the scan to one standing tree"
        )
    return np.array([centre[0], centre[1], trunk[:, 2].min()])


def _band(pts: np.ndarray, up: np.ndarray, h: float, start: float,
          columns: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(indices of the base band's points in ``pts`` (N, 3), their cluster labels, the big clusters:
    ``_base_clusters``, with ``columns``): the points from ``start`` up ``BASE_BAND`` of the height
    ``h`` in ``up`` (N,), at least the ``BASE_MIN`` lowest from ``start``."""
    above = up >= start
    band = np.flatnonzero(above & (up < start + BASE_BAND * h))
    if len(band) < BASE_MIN:
        band = np.flatnonzero(above)[np.argsort(up[above])[:BASE_MIN]]
    lab, big = _base_clusters(np.c_[pts[band, :2], up[band]], h, np.c_[pts[:, :2], up], columns)
    return band, lab, big


def _above_cut(pts: np.ndarray, up: np.ndarray, h: float, cut: float) -> None:
    """``find_root``'s several-trees check (``_band``: InputError) on the band from ``cut``, the top of the
    ground cut in ``up`` (N,), over ``pts`` (N, 3); when that band's largest cluster is a flat patch
    (``_flat``: ground left above the cut, the ground found lying under the real one, on the floor of
    outliers), once more on the band from ``LINK`` of the height ``h`` above the patch (its 90th
    percentile), where the trunks standing on it rise apart (two pines 3 apart among 10-15 %
    outliers: their patches joined into one cluster). The same above the band's largest cluster when
    it is no trunk column (``_trunk``) nor flat: patches with outliers linked to them, too thick to
    read flat, or one tree's patch with its trunk's foot in it (two pines 3 apart over the outliers'
    floor, 15 % outliers: the other trunk, 22-35 points, under 10 % of that band, was no big cluster;
    helper-171). Only clusters a trunk column rises from count there (``columns``): the top of a
    boulder by the trunk, left over the cut, stood 0.8 of the height apart from it on the toy tree."""
    band, lab, big = _band(pts, up, h, cut, columns=True)
    base = np.c_[pts[band, :2], up[band]]
    if len(big) and _flat(base[lab == big[0]], h):
        patch = base[lab == big[0]]
    else:  # the band's largest cluster is no trunk: patches with outliers linked, a trunk's foot in one
        patch = base[lab == np.argmax(np.bincount(lab))]
        if len(patch) < BASE_MIN or _trunk(*_columns(np.c_[pts[:, :2], up], [patch], h)[0]):
            return
    _band(pts, up, h, float(np.percentile(patch[:, 2], 90)) + LINK * h, columns=True)


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


def _base_clusters(base: np.ndarray, h: float, cloud: np.ndarray,
                   columns: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Cluster labels of the base band (links shorter than 2 % of height) and the big clusters that do
    not hang from the crown (``STANDING``; ``_no_column`` for all but the lowest; ``cloud`` (N, 3): the
    whole cloud), largest first; with ``columns``, only those a trunk column rises from (``_trunk``).
    InputError when two of those lie more than 10 % of the height apart (several trees). ``base`` and
    ``cloud`` hold x, y and the height above the ground."""
    lab = _link(base, LINK * h)
    sizes = np.bincount(lab)
    big = np.flatnonzero(sizes >= max(10, 0.1 * len(base)))
    big = big[np.argsort(-sizes[big])]
    fallen = _trunks_under_fallen_crown(base, lab, big, cloud, h)
    if fallen is not None:
        big = fallen
    elif len(big) >= 2:
        low = np.array([base[lab == c, 2].min() for c in big])
        dense = sizes[big] / np.maximum(base[:, 2].max() - low, 1e-9 * h)
        hanging = (low > low.min() + STANDING * h) & (dense < HANGING_SHARE * dense[0])
        column = _no_column(cloud, [base[lab == c] for c in big], h)
        column[np.argmin(low)] = False  # the lowest never hangs this way (an occluded trunk beside a bush
        hanging |= column  # is gappy and wide; weeping leaves may outnumber a thin trunk in the band)
        big = big[~hanging]
    if columns and len(big) >= 2:
        big = big[np.array([_trunk(core, ring) for core, ring in _columns(cloud, [base[lab == c] for c in big], h)])]
    if len(big) >= 2:
        cents = np.array([np.median(base[lab == c], axis=0) for c in big])
        sep = np.linalg.norm(cents[:, None, :2] - cents[None, :, :2], axis=2).max()
        if sep > 0.1 * h:
            if any(_flat(base[lab == c], h) for c in big):
                raise InputError(
                    f"point cloud: the lowest {BASE_BAND:.0%} of the cloud holds flat patches up to "
                    f"{sep:.3g} apart, not trunks: ground that is not one plane (a ridge, a hollow, a "
                    "slope over 27 degrees), or foliage lying on the ground? crop it away"
                )
            raise InputError(
                f"point cloud: {len(big)} separate trunks found {sep:.3g} apart at the base; "
                "decompose one tree at a time"
            )
    return lab, big


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


def _trunks_under_fallen_crown(base: np.ndarray, lab: np.ndarray, big: np.ndarray, cloud: np.ndarray,
                               h: float) -> np.ndarray | None:
    """The clusters of the base band that are trunks when its largest is a crown bent down to the
    ground, or when it has no big cluster (largest first); None when neither holds.

    The largest is such a crown when it is no trunk column but a mat, and so is every other big
    cluster that is no trunk: flatter than half its plan radius (stems in the band span its height),
    with the crown rising above it (each slab of its ``columns.column`` holds ``columns.MIN_SLAB``
    points; ground has nothing above it). (Asking the largest to be wider than a trunk held for 4 of
    12 downsampling seeds only: the mats often break into narrower pieces.) A trunk is a cluster of at least
    ``BASE_MIN`` points whose column is full (no slab under ``GAPPY`` of the fullest, none under
    ``MIN_SLAB``) and narrow (``columns.NARROW``). A weeping crown's leaves can outnumber a thin trunk
    in the band, and the root then went to them (the guiding elm bent down 90 %: 0.49 of the height
    from its trunk)."""
    from .columns import MIN_SLAB

    sizes = np.bincount(lab)
    cands = np.flatnonzero(sizes >= BASE_MIN)
    if not len(cands):
        return None
    cands = cands[np.argsort(-sizes[cands], kind="stable")]
    cols = _columns(cloud, [base[lab == c] for c in cands], h)
    trunk = np.array([_trunk(core, ring) for core, ring in cols], bool)
    mat = np.array([core.min() >= MIN_SLAB and np.ptp(base[lab == c, 2]) < 0.5 * plan_radius(base[lab == c], 90)
                    for c, (core, _) in zip(cands, cols)], bool)
    first = np.flatnonzero(cands == big[0])[0] if len(big) else None
    if first is not None and (trunk[first] or not mat[first]):
        return None  # the largest is a trunk, or no mat: the other rules decide
    others = np.isin(cands, big) & ~trunk
    if not trunk.any() or not mat[others].all():
        return None
    return cands[trunk]


def _trunk(core: np.ndarray, ring: np.ndarray) -> bool:
    """Whether a column (``columns.column``'s points per slab within its radius, ``core``, and round it,
    ``ring``) is a trunk's: full (no slab under ``GAPPY`` of the fullest nor under ``columns.MIN_SLAB``)
    and narrow (``columns.NARROW``)."""
    from .columns import MIN_SLAB, NARROW

    return bool(core.min() >= max(GAPPY * core.max(), MIN_SLAB) and core.sum() >= NARROW * (core.sum() + ring.sum()))


def _columns(cloud: np.ndarray, clusters: list[np.ndarray], h: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(core, ring) of ``columns.column`` rising from each cluster of the base band: within 1.5 times
    its 90th-percentile plan radius (at least 1 % of the height ``h``), from its lowest point."""
    from scipy.spatial import cKDTree

    from .columns import SPAN, column

    low = cloud[cloud[:, 2] < min(c[:, 2].min() for c in clusters) + (BASE_BAND + SPAN) * h]
    tree = cKDTree(low[:, :2])
    out = []
    for c in clusters:
        rho = max(1.5 * plan_radius(c, 90), 0.01 * h)
        out.append(column(tree, low, low[:, 2], np.median(c[:, :2], axis=0), float(c[:, 2].min()), rho, h))
    return out


def _no_column(cloud: np.ndarray, clusters: list[np.ndarray], h: float) -> np.ndarray:
    """(C,) bool: no trunk rises from the cluster of the base band (hanging leaves reaching the ground).

    Each cluster's column (``columns.column``: within 1.5 times its 90th-percentile plan radius, up
    ``columns.SPAN`` of the height ``h`` from its lowest point, in ``columns.SLABS`` slabs) is no
    trunk when one of its slabs holds under ``GAPPY`` of its fullest and under ``columns.NARROW`` of
    the column's points lie within its radius of the points within twice it. Each cluster is measured
    on its own, so a denser neighbour does not make a tree hang. None hangs when the largest cluster
    is wider than a trunk (``_flat``'s width).
    """
    from .columns import NARROW

    out = np.zeros(len(clusters), bool)
    if plan_radius(clusters[0], 90) > 0.5 * MAX_BASE_SPREAD * h:  # the largest is no trunk: a crown
        return out  # bent down to the ground, whose trunk would then hang
    for k, (core, ring) in enumerate(_columns(cloud, clusters, h)):
        out[k] = core.min() < GAPPY * core.max() and core.sum() < NARROW * (core.sum() + ring.sum())
    return out


def _flat(cluster: np.ndarray, h: float) -> bool:
    """A cluster of the base band that is a patch of ground: wider than half ``MAX_BASE_SPREAD`` of the
    height ``h`` (no trunk is) and than twice its own height."""
    r90 = plan_radius(cluster, 90)
    return r90 > 0.5 * MAX_BASE_SPREAD * h and float(np.ptp(cluster[:, 2])) < 0.5 * r90



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
