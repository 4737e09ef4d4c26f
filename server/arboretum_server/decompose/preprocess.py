"""Preprocessing (VRTree Appendix A): validate, remove the ground, downsample, find the trunk base, scale.

The paper downsamples every tree to 12,000 points and scales it to 0.8 m. We also find the root (the
trunk base), remove a ground disc when one is present, and refuse clouds that hold no single tree.
Normalised frame: ``p_work = (p_scan - root) * scale`` with the root at the origin and height 0.8 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.errors import InputError

from .columns import Column, trunk_columns
from .options import WORK_HEIGHT, DecomposeOptions

BASE_BAND = 0.03
"""Height band (fraction of the tree height) whose points locate the trunk base."""
BASE_MIN = 10
"""The base band holds at least this many points (a flat cloud's lowest 3 % holds one or two, whose
spread would read as a trunk's)."""
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
MAX_COORDINATE = 1e12
"""Largest coordinate magnitude read as a point (geocentric coordinates in millimetres stay under
1e10); beyond it squared distances overflow float64 long before 1e154."""
GAPPY = 0.25
"""A slab of a trunk's column holds at least this share of its fullest slab (``_no_column``)."""
MAX_BASE_SPREAD = 0.12
"""Largest 90th-percentile radius of the base band (fraction of height) that still is one trunk."""
STANDING = 0.01
"""A big cluster of the base band whose lowest point lies more than this fraction of the height above the
lowest cluster's, and that holds fewer points per metre of height than ``HANGING_SHARE`` of the largest
cluster's, hangs from the crown (a weeping branch's tips or leaves reaching into the band): it is no
second tree."""
HANGING_SHARE = 0.5
"""See ``STANDING``. Points are counted per metre between a cluster's lowest point and the band's top, so
a second trunk up a slope, whose lower part the band cuts off, still counts as a tree (and a stray point
under the trunk, which lowers the trunk's count, makes no other cluster hang)."""


@dataclass(frozen=True, eq=False)
class Prepared:
    """A cloud ready for decomposition, in the normalised frame."""

    points: np.ndarray
    """(N, 3) float64: points in the normalised frame (root at the origin, height 0.8)."""
    source_index: np.ndarray
    """(N,) int64: index of each point in the input array."""
    labels: np.ndarray | None
    """(N,) uint8 WOOD/LEAF labels given with the input, or None."""
    root_scan: np.ndarray
    """(3,) float64: the trunk base in the scan's frame."""
    scale: float
    """Normalised units per scan unit."""
    ground_removed: int
    """Number of input points removed as ground."""
    columns: tuple[Column, ...] = ()
    """Trunk-like columns away from the root, in the scan's frame and units (``columns.trunk_columns``):
    another tree standing higher?"""


def validate(points: np.ndarray, options: DecomposeOptions) -> np.ndarray:
    """Check ``points`` (N, 3+) and return the finite xyz (M, 3) float64; InputError otherwise."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise InputError(f"point cloud: expected an (N, 3) array, got shape {pts.shape}")
    pts = pts[:, :3]
    finite = np.isfinite(pts).all(axis=1)
    if finite.sum() < options.min_points:
        raise InputError(
            f"point cloud: {int(finite.sum())} usable points, need at least {options.min_points} to decompose a tree"
        )
    big = float(np.abs(pts[finite]).max())
    if big > MAX_COORDINATE:
        raise InputError(
            f"point cloud: coordinates up to {big:.3g}, beyond {MAX_COORDINATE:.0e} in any unit; "
            "a file read in the wrong format or units?"
        )
    if np.ptp(pts[finite, 2]) <= 0:
        raise InputError("point cloud: all points lie at one height; this is not a tree")
    return pts


def _plan_radius(q: np.ndarray, percent: float) -> float:
    """The ``percent``-th percentile of the plan-view distances of ``q`` (M, 3) from their median."""
    return float(np.percentile(np.linalg.norm(q[:, :2] - np.median(q[:, :2], axis=0), axis=1), percent))


def _spread(q: np.ndarray) -> float:
    """Median plan-view distance of ``q`` (M, 3) from its median; inf for fewer than 5 points."""
    return np.inf if len(q) < 5 else _plan_radius(q, 50)


def lowest_per_cell(pts: np.ndarray, cell: float) -> np.ndarray:
    """The lowest point (M, 3) of ``pts`` (N, 3) in each ``cell`` x ``cell`` column of the xy plane
    (columns widened so that no axis holds more than 2 ** 20 of them)."""
    cell = max(cell, float(np.ptp(pts[:, :2], axis=0).max()) / 2 ** 20, 1e-300)
    key = np.floor((pts[:, :2] - pts[:, :2].min(axis=0)) / cell).astype(np.int64)
    key = key[:, 0] * (int(key[:, 1].max()) + 1) + key[:, 1]
    order = np.lexsort((pts[:, 2], key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return pts[order[first]]


def ground_plane(pts: np.ndarray, band_frac: float) -> np.ndarray | None:
    """(a, b, c) of the ground z = a x + b y + c under ``pts`` (N, 3), or None when there is none.

    RANSAC (``GROUND_TRIES`` triples, a fixed seed) over the lowest point of every ``GROUND_CELL``
    column (scored on at most ``GROUND_SAMPLE`` of them): the plane, at most ``GROUND_TILT`` steep,
    that most of those lie within half of ``band_frac`` of the height of, refitted by least squares to
    all of them that do.
    """
    h = float(np.ptp(pts[:, 2]))
    low = lowest_per_cell(pts, GROUND_CELL * h)
    if len(low) < 20:
        return None
    rng = np.random.default_rng(0)  # its own: the downsampling stream stays as it was
    some = low if len(low) <= GROUND_SAMPLE else low[rng.choice(len(low), GROUND_SAMPLE, replace=False)]
    tol = band_frac * h / 2
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


def find_ground(pts: np.ndarray, band_frac: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(N,) bool ground points of ``pts`` (N, 3), flat or sloped, and the ground plane (a, b, c) or None
    when there is no ground.

    The ground is the plane of ``ground_plane`` when at most ``GROUND_BELOW`` of the points lie below it
    and the points within half of ``band_frac`` of the height of it spread ``GROUND_WIDER`` times wider
    than the trunk: the narrowest of the slices ``band_frac`` / 3 thick from ``band_frac`` to
    6 ``band_frac`` above it (low branches widen some). Removed: everything below the first slice from
    ``band_frac`` up that is trunk-wide again (at most twice the trunk's spread), grass and a rough
    surface with it.
    """
    none = np.zeros(len(pts), bool), None
    h = float(np.ptp(pts[:, 2]))
    coef = ground_plane(pts, band_frac) if h > 0 else None
    if coef is None:
        return none
    up = pts[:, 2] - (pts[:, :2] @ coef[:2] + coef[2])  # height above the ground
    step = band_frac * float(up.max()) / 3  # of the tree's height: a slope's rise is not the tree's
    near = np.flatnonzero((up > -step) & (up < 30 * step))
    slab = np.floor(up[near] / step).astype(np.int64)

    def spread(k: int) -> float:
        return _spread(pts[near[slab == k]])

    trunk = min(spread(k) for k in range(3, 18))
    if ((up < -1.5 * step).sum() > GROUND_BELOW * len(pts) or not np.isfinite(trunk)
            or _spread(pts[np.abs(up) < 1.5 * step]) < GROUND_WIDER * trunk):
        return none
    cut = next((k for k in range(3, 30) if spread(k) < 2 * trunk), 3)
    return up < cut * step, coef


def find_root(pts: np.ndarray, ground: np.ndarray | None = None) -> np.ndarray:
    """(3,) trunk base of ``pts`` (N, 3): centre of the largest cluster in the lowest band, at its lowest z.

    The band is the lowest ``BASE_BAND`` of the height, measured from the ``ground`` plane (a, b, c) when
    one was found (a second tree up the slope stands in it too), else from the lowest point.
    InputError when the band holds several well-separated trunks (clusters hanging from the crown aside:
    ``STANDING``, ``_no_column``), or when its largest cluster spreads too wide to be one trunk base.
    A second tree standing higher than the band is not refused here: see ``columns.trunk_columns``.
    """
    z = pts[:, 2]
    h = np.ptp(z)
    up = z if ground is None else z - (pts[:, :2] @ ground[:2] + ground[2])
    band = np.flatnonzero(up < up.min() + BASE_BAND * h)
    if len(band) < BASE_MIN:
        band = np.argsort(up)[:BASE_MIN]
    base = pts[band]
    lab, big = _base_clusters(np.c_[base[:, :2], up[band]], h, np.c_[pts[:, :2], up])
    trunk = base[lab == big[0]] if len(big) else base
    centre = np.median(trunk[:, :2], axis=0)
    r90 = _plan_radius(trunk, 90)
    if r90 > MAX_BASE_SPREAD * h:
        raise InputError(
            f"point cloud: no trunk base found (the lowest {BASE_BAND:.0%} of the cloud spreads "
            f"{r90:.3g} wide for a height of {h:.3g}); crop the scan to one standing tree"
        )
    return np.array([centre[0], centre[1], trunk[:, 2].min()])


def _base_clusters(base: np.ndarray, h: float, cloud: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cluster labels of the base band (links shorter than 2 % of height) and the big clusters that do
    not hang from the crown (``STANDING``; ``_no_column`` for all but the lowest; ``cloud`` (N, 3): the
    whole cloud), largest first. InputError when two of those lie more than 10 % of the height apart (several
    trees). ``base`` and ``cloud`` hold x, y and the height above the ground."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(base).query_pairs(0.02 * h, output_type="ndarray")
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(base),) * 2)
    _, lab = connected_components(adj, directed=False)
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

    The largest is such a crown when it is wider than a trunk (``_flat``'s width), and it and every
    other big cluster that is no trunk is a mat (flatter than half its plan radius: stems in the band
    span its height) with the crown rising above it (each slab of its ``columns.column`` holds
    ``columns.MIN_SLAB`` points; ground has nothing above it). A trunk is a cluster of at least
    ``BASE_MIN`` points whose column is full (no slab under ``GAPPY`` of the fullest, none under
    ``MIN_SLAB``) and narrow (``columns.NARROW``). A weeping crown's leaves can outnumber a thin trunk
    in the band, and the root then went to them (the guiding elm bent down 90 %: 0.49 of the height
    from its trunk)."""
    from .columns import MIN_SLAB, NARROW

    if len(big) and _plan_radius(base[lab == big[0]], 90) <= 0.5 * MAX_BASE_SPREAD * h:
        return None
    sizes = np.bincount(lab)
    cands = np.flatnonzero(sizes >= BASE_MIN)
    if not len(cands):
        return None
    cands = cands[np.argsort(-sizes[cands], kind="stable")]
    cols = _columns(cloud, [base[lab == c] for c in cands], h)
    trunk = np.array([core.min() >= max(GAPPY * core.max(), MIN_SLAB) and core.sum() >= NARROW * (core.sum() + ring.sum())
                      for core, ring in cols], bool)
    mat = np.array([core.min() >= MIN_SLAB and np.ptp(base[lab == c, 2]) < 0.5 * _plan_radius(base[lab == c], 90)
                    for c, (core, _) in zip(cands, cols)], bool)
    others = np.isin(cands, big) & ~trunk
    if not trunk.any() or not mat[others].all():
        return None
    return cands[trunk]


def _columns(cloud: np.ndarray, clusters: list[np.ndarray], h: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(core, ring) of ``columns.column`` rising from each cluster of the base band: within 1.5 times
    its 90th-percentile plan radius (at least 1 % of the height ``h``), from its lowest point."""
    from scipy.spatial import cKDTree

    from .columns import SPAN, column

    low = cloud[cloud[:, 2] < min(c[:, 2].min() for c in clusters) + (BASE_BAND + SPAN) * h]
    tree = cKDTree(low[:, :2])
    out = []
    for c in clusters:
        rho = max(1.5 * _plan_radius(c, 90), 0.01 * h)
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
    if _plan_radius(clusters[0], 90) > 0.5 * MAX_BASE_SPREAD * h:  # the largest is no trunk: a crown
        return out  # bent down to the ground, whose trunk would then hang
    for k, (core, ring) in enumerate(_columns(cloud, clusters, h)):
        out[k] = core.min() < GAPPY * core.max() and core.sum() < NARROW * (core.sum() + ring.sum())
    return out


def _flat(cluster: np.ndarray, h: float) -> bool:
    """A cluster of the base band that is a patch of ground: wider than half ``MAX_BASE_SPREAD`` of the
    height ``h`` (no trunk is) and than twice its own height."""
    r90 = _plan_radius(cluster, 90)
    return r90 > 0.5 * MAX_BASE_SPREAD * h and float(np.ptp(cluster[:, 2])) < 0.5 * r90


def prepare(
    points: np.ndarray,
    options: DecomposeOptions,
    rng: np.random.Generator,
    labels: np.ndarray | None = None,
) -> Prepared:
    """Validate, remove ground, downsample to ``options.points`` and normalise. InputError on bad input."""
    check_points(options)
    pts = validate(points, options)
    keep = np.isfinite(pts).all(axis=1)
    ground, plane = find_ground(pts[keep], options.ground_band)
    idx = np.flatnonzero(keep)[~ground]
    if len(idx) < options.min_points:
        raise InputError(f"point cloud: only {len(idx)} points remain after removing the ground")
    if options.points and len(idx) > options.points:
        idx = np.sort(rng.choice(idx, options.points, replace=False))
    sub = pts[idx]
    _check_counts(len(sub), options)
    root = find_root(sub, plane)
    up = sub[:, 2] if plane is None else sub[:, 2] - (sub[:, :2] @ plane[:2] + plane[2])
    cols = trunk_columns(sub, root, up)
    height = float(sub[:, 2].max() - root[2])
    scale = WORK_HEIGHT / height
    lab = None
    if labels is not None and options.use_labels:
        lab = np.asarray(labels).reshape(-1)
        if lab.shape[0] != len(pts):
            raise InputError(f"labels: {lab.shape[0]} labels for {len(pts)} points")
        lab = (lab[idx] > 0).astype(np.uint8)
    return Prepared((sub - root) * scale, idx, lab, root, scale, int(ground.sum()), tuple(cols))


def check_points(options: DecomposeOptions, name: str = "points") -> None:
    """InputError when downsampling to ``options.points`` leaves too few points (``name``: the option's
    name in the message, e.g. the command's ``--points``)."""
    if 0 < options.points < options.min_points:
        raise InputError(f"{name} {options.points} leaves too few points to decompose a tree "
                         f"(at least {options.min_points}, or 0 to keep all)")


POINTS_PER_LOBE = 10
"""Fewest points per lobe on average that a decomposition accepts (an alpha shape needs 5)."""


def _check_counts(n: int, o: DecomposeOptions) -> None:
    """InputError when N_m or N_l cannot be met on ``n`` points."""
    n_main, n_lobes = o.counts()
    if n_main > o.fps_candidates:
        raise InputError(f"main branches: {n_main} asked, at most {o.fps_candidates} (the candidate paths)")
    if n_lobes > n // POINTS_PER_LOBE:
        raise InputError(f"lobes: {n_lobes} asked for {n} points, at most {n // POINTS_PER_LOBE} "
                         f"({POINTS_PER_LOBE} points per lobe)")
