"""Preprocessing (VRTree Appendix A): validate, remove the ground, downsample, find the trunk base, scale.

The paper downsamples every tree to 12,000 points and scales it to 0.8 m. We also find the root (the
trunk base), remove a ground disc when one is present, and refuse clouds that hold no single tree.
Normalised frame: ``p_work = (p_scan - root) * scale`` with the root at the origin and height 0.8 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.errors import InputError

from .options import WORK_HEIGHT, DecomposeOptions

BASE_BAND = 0.03
"""Height band (fraction of the tree height) whose points locate the trunk base."""
BASE_MIN = 10
"""The base band holds at least this many points (a flat cloud's lowest 3 % holds one or two, whose
spread would read as a trunk's)."""
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
    if np.ptp(pts[finite, 2]) <= 0:
        raise InputError("point cloud: all points lie at one height; this is not a tree")
    return pts


def ground_mask(pts: np.ndarray, band_frac: float) -> np.ndarray:
    """(N,) bool: points of a ground disc under the trunk (none if the base is already narrow)."""
    z = pts[:, 2]
    z0, h = z.min(), np.ptp(z)
    band = band_frac * h

    def spread(lo: float, hi: float) -> float:
        sel = pts[(z >= lo) & (z < hi), :2]
        if len(sel) < 5:
            return 0.0
        return float(np.percentile(np.linalg.norm(sel - np.median(sel, axis=0), axis=1), 90))

    trunk = spread(z0 + 3 * band, z0 + 5 * band)
    if trunk <= 0 or spread(z0, z0 + band) < 3 * trunk:
        return np.zeros(len(pts), bool)
    cut = z0 + band
    for k in range(1, 30):  # climb until the slice is trunk-wide again
        lo = z0 + k * band / 3
        if spread(lo, lo + band / 3) < 2 * trunk:
            cut = lo
            break
    return z < cut


def find_root(pts: np.ndarray) -> np.ndarray:
    """(3,) trunk base of ``pts`` (N, 3): centre of the largest cluster in the lowest band, at its lowest z.

    InputError when the band holds several well-separated trunks (clusters hanging from the crown aside,
    ``STANDING``), or when its largest cluster spreads too wide to be one trunk base.
    """
    z = pts[:, 2]
    h = np.ptp(z)
    base = pts[z < z.min() + BASE_BAND * h]
    if len(base) < BASE_MIN:
        base = pts[np.argsort(z)[:BASE_MIN]]
    lab, big = _base_clusters(base, h)
    trunk = base[lab == big[0]] if len(big) else base
    centre = np.median(trunk[:, :2], axis=0)
    r90 = float(np.percentile(np.linalg.norm(trunk[:, :2] - centre, axis=1), 90))
    if r90 > MAX_BASE_SPREAD * h:
        raise InputError(
            f"point cloud: no trunk base found (the lowest {BASE_BAND:.0%} of the cloud spreads "
            f"{r90:.3g} wide for a height of {h:.3g}); crop the scan to one standing tree"
        )
    return np.array([centre[0], centre[1], trunk[:, 2].min()])


def _base_clusters(base: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Cluster labels of the base band (links shorter than 2 % of height) and the big clusters that do
    not hang from the crown (``STANDING``), largest first. InputError when two of those lie more
    than 10 % of the height apart (several trees)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(base).query_pairs(0.02 * h, output_type="ndarray")
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(base),) * 2)
    _, lab = connected_components(adj, directed=False)
    sizes = np.bincount(lab)
    big = np.flatnonzero(sizes >= max(10, 0.1 * len(base)))
    big = big[np.argsort(-sizes[big])]
    if len(big) >= 2:
        low = np.array([base[lab == c, 2].min() for c in big])
        dense = sizes[big] / np.maximum(base[:, 2].max() - low, 1e-9 * h)
        hanging = (low > low.min() + STANDING * h) & (dense < HANGING_SHARE * dense[0])
        big = big[~hanging]
    if len(big) >= 2:
        cents = np.array([np.median(base[lab == c], axis=0) for c in big])
        sep = np.linalg.norm(cents[:, None, :2] - cents[None, :, :2], axis=2).max()
        if sep > 0.1 * h:
            raise InputError(
                f"point cloud: {len(big)} separate trunks found {sep:.3g} apart at the base; "
                "decompose one tree at a time"
            )
    return lab, big


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
    ground = ground_mask(pts[keep], options.ground_band)
    idx = np.flatnonzero(keep)[~ground]
    if len(idx) < options.min_points:
        raise InputError(f"point cloud: only {len(idx)} points remain after removing the ground")
    if options.points and len(idx) > options.points:
        idx = np.sort(rng.choice(idx, options.points, replace=False))
    sub = pts[idx]
    _check_counts(len(sub), options)
    root = find_root(sub)
    height = float(sub[:, 2].max() - root[2])
    scale = WORK_HEIGHT / height
    lab = None
    if labels is not None and options.use_labels:
        lab = np.asarray(labels).reshape(-1)
        if lab.shape[0] != len(pts):
            raise InputError(f"labels: {lab.shape[0]} labels for {len(pts)} points")
        lab = (lab[idx] > 0).astype(np.uint8)
    return Prepared((sub - root) * scale, idx, lab, root, scale, int(ground.sum()))


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
