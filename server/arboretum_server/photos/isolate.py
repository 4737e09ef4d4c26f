"""The tree out of a photogrammetric cloud: ground plane removed, main cluster kept, Z up, scaled.

SfM clouds come in an arbitrary frame and scale, so every distance here is relative to the cloud's size
``L`` (the 90th percentile distance of the points from their median) or to its point spacing ``h`` (the
median distance to the 8th nearest neighbour). Steps:

1. Up direction: the mean of the cameras' image-up directions when cameras are known (people hold
   cameras upright), which also decides the sign of the ground normal.
2. Ground: RANSAC plane fit (``ransac_iterations`` triples, inliers within ``ground_threshold * L``),
   accepted when it holds ``min_ground_fraction`` of the points, has at most ``max_below_fraction`` of
   them below it, and (with cameras) its normal lies within
   ``max_tilt_deg`` of the cameras' up; refined by least squares on its inliers. Without a ground plane the
   up is the cameras' up, else the cloud's principal axis.
3. Orient: rotate the up direction (ground normal) to +Z; drop points on or below the ground.
4. Main cluster: connected components of the graph joining points closer than ``cluster_factor * h``;
   the largest is the tree.
5. Place and scale: the trunk base (``pointio.trunk_base``; its Z on the ground plane when there is
   one) to the origin, the height (top above the ground) to ``height`` metres (VRTree 4.1: 0.8 m).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.pointio import trunk_base


@dataclass(frozen=True)
class IsolateOptions:
    """Parameters of ``isolate``."""

    height: float = 0.8
    """Output tree height (Z extent), metres. VRTree section 4.1 scales every scan to 0.8 m."""
    ground_threshold: float = 0.02
    """RANSAC inlier distance to the ground plane, as a fraction of the cloud size L."""
    ransac_iterations: int = 500
    """Random point triples tried by the plane fit."""
    min_ground_fraction: float = 0.05
    """Smallest fraction of the points a plane must hold to count as the ground."""
    max_below_fraction: float = 0.05
    """Largest fraction of the points a ground plane may have below it (a slice through the crown has many)."""
    max_tilt_deg: float = 35.0
    """Largest angle between a ground plane's normal and the cameras' mean up (with cameras)."""
    cluster_factor: float = 4.0
    """Points closer than this times the spacing h join one cluster."""
    min_points: int = 20
    """Fewest points the kept tree may have."""
    seed: int = 0
    """Seed of the RANSAC sampling."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.height) and self.height > 0):
            raise InputError(f"height must be a number > 0 metres, got {self.height}")


@dataclass(frozen=True, eq=False)
class Isolated:
    """The tree cut out of a cloud, Z up, trunk base at the origin, scaled to the asked height."""

    points: np.ndarray
    """(M, 3) float64, metres, Z up: the tree's points."""
    index: np.ndarray
    """(M,) int64: index of each kept point in the input cloud."""
    T_out_in: np.ndarray
    """(4, 4) float64 similarity: ``p_out = T[:3, :3] @ p_in + T[:3, 3]`` (rotation times scale)."""
    stats: dict = field(default_factory=dict)
    """ground_found, ground_points, up_source ('ground', 'cameras' or 'pca'), clusters, kept, scale."""


def isolate(points: np.ndarray, options: IsolateOptions = IsolateOptions(),
            camera_up: np.ndarray | None = None) -> Isolated:
    """Cut the tree out of ``points`` (N, 3), any frame; ``camera_up`` (V, 3) image-up directions."""
    o = options
    pts = np.asarray(points, np.float64)
    if len(pts) < o.min_points:
        raise InputError(f"the reconstruction has {len(pts)} points; at least {o.min_points} are needed")
    L = float(np.percentile(np.linalg.norm(pts - np.median(pts, axis=0), axis=1), 90)) or 1.0
    up_ref = _camera_up(camera_up)
    rng = np.random.default_rng(o.seed)
    plane = fit_ground(pts, o.ground_threshold * L, o, rng, up_ref)
    if plane is not None:
        up, offset, source = plane[0], plane[1], "ground"
    else:
        up = up_ref if up_ref is not None else principal_up(pts)
        offset, source = float(np.percentile(pts @ up, 1)), ("cameras" if up_ref is not None else "pca")
    R = rotation_to_z(up)
    z = pts @ up - offset
    above = np.flatnonzero(z > o.ground_threshold * L)
    tree, n_clusters = main_cluster(pts[above] @ R.T, o.cluster_factor)
    keep = above[tree]
    if len(keep) < o.min_points:
        raise InputError(f"only {len(keep)} points stand above the ground in one cluster; "
                         f"at least {o.min_points} are needed (is a tree in the photographs?)")
    rotated = pts[keep] @ R.T
    base = trunk_base(rotated)
    if plane is not None:
        base[2] = offset  # the tree stands on the ground: height counts from the plane
    extent = float(rotated[:, 2].max() - base[2])
    s = o.height / max(extent, 1e-12)
    T = np.eye(4)
    T[:3, :3] = s * R
    T[:3, 3] = -s * base
    stats = {"ground_found": plane is not None, "ground_points": int(plane[2]) if plane else 0,
             "up_source": source, "clusters": n_clusters, "kept": len(keep), "input": len(pts), "scale": s}
    return Isolated(s * (rotated - base), keep, T, stats)


def apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (N, 3) mapped by the 4x4 similarity ``T``."""
    return np.asarray(points, np.float64) @ T[:3, :3].T + T[:3, 3]


def _camera_up(camera_up: np.ndarray | None) -> np.ndarray | None:
    if camera_up is None or len(camera_up) == 0:
        return None
    m = np.asarray(camera_up, np.float64).mean(axis=0)
    n = float(np.linalg.norm(m))
    return m / n if n > 0.3 else None  # cameras disagree about up: don't trust them


def fit_ground(pts: np.ndarray, threshold: float, o: IsolateOptions, rng: np.random.Generator,
               up_ref: np.ndarray | None) -> tuple[np.ndarray, float, int] | None:
    """(unit normal, offset, inlier count) of the ground plane ``n . p = offset``, or None.

    The normal points along ``up_ref`` (without it: to the side holding most of the other points).
    """
    tri = pts[rng.integers(0, len(pts), size=(o.ransac_iterations, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n = n[ok] / norm[ok, None]
    d = (n * tri[ok, 0]).sum(axis=1)
    if up_ref is not None:
        n, d = n * np.sign(n @ up_ref)[:, None], d * np.sign(n @ up_ref)
        ok = n @ up_ref >= np.cos(np.radians(o.max_tilt_deg))
        n, d = n[ok], d[ok]
    if len(n) == 0:
        return None
    counts = np.zeros(len(n), np.int64)
    for k in range(len(n)):
        dist = pts @ n[k] - d[k]
        below, above = int((dist < -threshold).sum()), int((dist > threshold).sum())
        if up_ref is None and below > above:
            n[k], d[k], below, above = -n[k], -d[k], above, below
        if below <= o.max_below_fraction * len(pts):  # the ground has (almost) nothing under it
            counts[k] = len(pts) - below - above
    best = int(counts.argmax())
    if counts[best] < o.min_ground_fraction * len(pts):
        return None
    inl = pts[np.abs(pts @ n[best] - d[best]) < threshold]
    normal, offset = _lsq_plane(inl, n[best])
    return normal, offset, len(inl)


def _lsq_plane(pts: np.ndarray, hint: np.ndarray) -> tuple[np.ndarray, float]:
    c = pts.mean(axis=0)
    normal = np.linalg.svd(pts - c, full_matrices=False)[2][-1]
    normal = normal if normal @ hint >= 0 else -normal
    return normal, float(normal @ c)


def principal_up(pts: np.ndarray) -> np.ndarray:
    """The cloud's principal axis, pointing from the denser end (the trunk's base) to the sparser."""
    c = pts - pts.mean(axis=0)
    axis = np.linalg.svd(c, full_matrices=False)[2][0]
    t = c @ axis
    return axis if np.abs(t[t > 0]).mean() * (t > 0).sum() > np.abs(t[t < 0]).mean() * (t < 0).sum() else -axis


def rotation_to_z(up: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) taking the unit vector ``up`` to +Z (the shortest turn)."""
    u = np.asarray(up, np.float64) / np.linalg.norm(up)
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(u, z), float(u @ z)
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def main_cluster(pts: np.ndarray, factor: float, k: int = 8) -> tuple[np.ndarray, int]:
    """Indices of the largest connected cluster of ``pts`` (N, 3) and the number of clusters.

    Two points join when closer than ``factor`` times the median distance to the k-th neighbour.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    if len(pts) <= k:
        return np.arange(len(pts)), 1
    tree = cKDTree(pts)
    h = float(np.median(tree.query(pts, k + 1)[0][:, -1]))
    pairs = tree.query_pairs(factor * max(h, 1e-12), output_type="ndarray")
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(pts), len(pts)))
    n, lab = connected_components(g, directed=False)
    return np.flatnonzero(lab == np.bincount(lab).argmax()), int(n)
