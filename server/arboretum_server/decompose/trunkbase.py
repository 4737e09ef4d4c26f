"""The trunk base (the root) of a cloud, and the checks that it holds one standing tree (ours).

``find_root`` clusters the lowest ``BASE_BAND`` of the height and puts the root on the largest
cluster that is a trunk. Clusters that hang from the crown (a weeping branch's leaves: ``STANDING``,
``_no_column``) or lie on the ground (a crown bent down to it: ``_trunks_under_fallen_crown``) are
no trunks; separate trunks are refused, in the band and, when the ground cut reaches over it, just
above the cut (``_above_cut``: another tree's foot cut with the ground). A second tree standing higher
than the band is ``columns.trunk_columns``' job.

Linked points, lone points and ``plan_radius`` are in ``trunkbase_links``; a piece apart under the tree
(``detached``, ``under``, re-exported here) in ``trunkbase_piece`` (split in three in session 25).
"""

from __future__ import annotations

import numpy as np

from arboretum_library.errors import InputError

from .trunkbase_links import BASE_MIN, LINK, _dense_start, _link, _strewn, plan_radius
from .trunkbase_piece import detached, under

__all__ = ["detached", "find_root", "plan_radius", "under"]

BASE_BAND = 0.03
"""Height band (fraction of the tree height) whose points locate the trunk base."""
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
HANGING_SHARE = 0.5
"""See ``STANDING``. Points are counted per metre between a cluster's lowest point and the band's top, so
a second trunk up a slope, whose lower part the band cuts off, still counts as a tree (and a stray point
under the trunk, which lowers the trunk's count, makes no other cluster hang)."""
FLOOR_UNDER = 0.05
"""When the base band starts more than this fraction of the height above the ground found, that ground is
the floor of outliers strewn under the trees, not theirs, and its tilt is noise: ``find_root``'s
several-trees check is made on the heights as given too (two pines 6 apart, no ground, 5 % uniform
outliers: a floor tilted 0.22 put their feet 2.3 and 3.6 over it, in no one band; helper-171)."""


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
