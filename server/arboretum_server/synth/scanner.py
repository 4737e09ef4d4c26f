"""A virtual terrestrial scanner: a labelled point cloud sampled analytically from a ``TreeTruth``.

The model, step by step (all in metres, Z up):

1. Surfaces. Every skeleton edge (parent -> child) is a truncated cone with the two nodes' radii; every
   leaf is the ellipse inscribed in its card (``arboretum_library.truth``). ``oversample * points``
   candidate samples are drawn uniformly by area over all of them, each remembering its label (wood 0,
   leaf 1) and branch id (a cone gets its child node's branch; a leaf the branch of its host node).
2. Scanners. ``scanners`` stations stand evenly on a circle around the trunk at ``scanner_height``.
3. Occlusion, per station, by splatting into a spherical depth image: each candidate facing the
   station (cones are one-sided, leaves two-sided) falls into a pixel of an equal-angle
   azimuth/elevation grid; a pixel sees its nearest candidate and every candidate within
   ``depth_tolerance`` behind it. Coarse (the pixel, not the beam, decides), fast (one sort per station).
   The pixel size is chosen so that the candidates' angular bounding box holds ``candidates / 4`` pixels.
4. Returns. Each visible (candidate, station) pair is a return, moved along its ray by Gaussian range
   noise (``noise``, the standard deviation).
5. Missing data. Returns whose azimuth about the trunk axis falls in the wedge ``missing_sector``
   degrees wide from ``missing_azimuth`` (VRTree's incomplete clouds), or inside ``missing_box``, go.
6. Budget. Exactly ``points`` returns are drawn at random without replacement; when occlusion and the
   missing region leave fewer, all of them are returned (fewer than asked).

Leaf-off mode drops the leaves before step 1 (they neither return nor occlude). Same truth, options and
seed: the same cloud.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from arboretum_library.geometry import quat_to_matrix
from arboretum_library.model import LEAF, WOOD
from arboretum_library.truth import LEAF_WIDTH_RATIO, TreeTruth


@dataclass(frozen=True)
class ScanOptions:
    """Parameters of the virtual scan."""

    points: int = 12_000
    """Point budget N: returned exactly, unless occlusion leaves fewer."""
    scanners: int = 4
    """Stations K, evenly spaced on a circle around the trunk."""
    distance: float | None = None
    """Circle radius, metres; None: 1.5 x the larger of the tree's height and crown diameter."""
    scanner_height: float = 1.5
    """Station height above the root, metres."""
    noise: float = 0.003
    """Range noise: standard deviation along the ray, metres."""
    oversample: float = 8.0
    """Candidate surface samples per output point."""
    depth_tolerance: float = 0.02
    """A pixel also sees candidates up to this far behind its nearest one, metres."""
    leaf_off: bool = False
    """Scan without leaves."""
    missing_sector: float = 0.0
    """Width in degrees of an azimuth wedge about the trunk with no points (0: none)."""
    missing_azimuth: float = 0.0
    """Start of the wedge, degrees counter-clockwise from +X."""
    missing_box: tuple[float, float, float, float, float, float] | None = None
    """(xmin, ymin, zmin, xmax, ymax, zmax) region with no points, metres; None: none."""


@dataclass(frozen=True, eq=False)
class Scan:
    """A labelled virtual scan."""

    points: np.ndarray
    """(N, 3) float64, metres, world (Z up)."""
    labels: np.ndarray
    """(N,) uint8: WOOD (0) or LEAF (1)."""
    branch_ids: np.ndarray
    """(N,) int32: the truth's branch id of the surface each point came from."""
    stations: np.ndarray
    """(K, 3) float64: scanner positions."""


@dataclass
class Surface:
    """Candidate surface samples."""

    points: np.ndarray
    normals: np.ndarray
    labels: np.ndarray
    branch_ids: np.ndarray
    two_sided: np.ndarray


def sample_wood(truth: TreeTruth, m: int, rng: np.random.Generator) -> Surface:
    """``m`` samples uniform by area on the truncated cones of the skeleton edges."""
    child = np.arange(1, truth.node_count)
    a, b = truth.positions[truth.parent[child]], truth.positions[child]
    ra, rb = truth.radii[truth.parent[child]], truth.radii[child]
    axis = b - a
    length = np.linalg.norm(axis, axis=1)
    area = np.pi * (ra + rb) * length
    e = rng.choice(len(child), size=m, p=area / area.sum())
    u, psi = rng.random(m), rng.uniform(0, 2 * np.pi, m)
    n1, n2 = _perpendiculars(axis[e] / length[e, None])
    normal = np.cos(psi)[:, None] * n1 + np.sin(psi)[:, None] * n2
    r = ra[e] + u * (rb[e] - ra[e])
    pts = a[e] + u[:, None] * axis[e] + r[:, None] * normal
    return Surface(
        pts, normal, np.full(m, WOOD, np.uint8), truth.branch_id[child[e]], np.zeros(m, bool)
    )


def sample_leaves(truth: TreeTruth, m: int, rng: np.random.Generator) -> Surface:
    """``m`` samples uniform by area on the leaf ellipses."""
    sizes = truth.leaf_sizes
    j = rng.choice(truth.leaf_count, size=m, p=sizes**2 / (sizes**2).sum())
    rad, ang = np.sqrt(rng.random(m)), rng.uniform(0, 2 * np.pi, m)
    x = 0.5 * sizes[j] * rad * np.cos(ang)
    y = 0.5 * LEAF_WIDTH_RATIO * sizes[j] * rad * np.sin(ang)
    R = np.stack([quat_to_matrix(q) for q in truth.leaf_wxyz])[j]
    pts = truth.leaf_positions[j] + x[:, None] * R[:, :, 0] + y[:, None] * R[:, :, 1]
    bid = truth.branch_id[truth.leaf_node[j]]
    return Surface(pts, R[:, :, 2], np.full(m, LEAF, np.uint8), bid, np.ones(m, bool))


def _perpendiculars(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (M, 3) perpendicular to unit ``t`` (M, 3) and to each other."""
    helper = np.where(np.abs(t[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    n1 = np.cross(t, helper)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    return n1, np.cross(t, n1)


def stations(truth: TreeTruth, opts: ScanOptions) -> np.ndarray:
    """(K, 3) scanner positions on a circle about the root."""
    pos = truth.positions
    root = pos[0]
    if opts.distance is None:
        crown = 2 * np.linalg.norm(pos[:, :2] - root[:2], axis=1).max()
        dist = 1.5 * max(float(np.ptp(pos[:, 2])), float(crown), 1e-3)
    else:
        dist = opts.distance
    ang = 2 * np.pi * np.arange(opts.scanners) / opts.scanners + np.pi / opts.scanners
    return root + np.stack(
        [dist * np.cos(ang), dist * np.sin(ang), np.full(len(ang), opts.scanner_height)], 1
    )


def visible(surf: Surface, station: np.ndarray, pixel: float, tol: float) -> np.ndarray:
    """Indices of the candidates seen from ``station`` (spherical depth-image splatting)."""
    d = surf.points - station
    rng_ = np.linalg.norm(d, axis=1)
    facing = surf.two_sided | ((surf.normals * d).sum(axis=1) < 0)
    idx = np.flatnonzero(facing)
    az = np.arctan2(d[idx, 1], d[idx, 0])
    el = np.arcsin(np.clip(d[idx, 2] / rng_[idx], -1.0, 1.0))
    cols = math.ceil(2 * np.pi / pixel) + 1
    pix = np.floor((el + np.pi / 2) / pixel).astype(np.int64) * cols + np.floor(
        (az + np.pi) / pixel
    ).astype(np.int64)
    order = np.lexsort((rng_[idx], pix))
    pix_sorted = pix[order]
    first = np.ones(len(order), bool)
    first[1:] = pix_sorted[1:] != pix_sorted[:-1]
    nearest = np.maximum.accumulate(np.where(first, np.arange(len(order)), 0))
    r_sorted = rng_[idx][order]
    keep = r_sorted <= r_sorted[nearest] + tol
    return idx[order[keep]]


def auto_pixel(points: np.ndarray, station: np.ndarray) -> float:
    """Pixel size (radians) so that the candidates' angular bounding box holds len(points) / 4 pixels."""
    d = points - station
    mid = d.mean(axis=0)
    az = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - math.atan2(mid[1], mid[0]))))
    el = np.arcsin(np.clip(d[:, 2] / np.linalg.norm(d, axis=1), -1.0, 1.0))
    solid = (
        max(float(np.ptp(az)), 1e-6) * max(float(np.ptp(el)), 1e-6) * math.cos(float(np.median(el)))
    )
    return math.sqrt(solid / max(len(points) / 4, 1))


def scan(truth: TreeTruth, opts: ScanOptions, rng: np.random.Generator) -> Scan:
    """Sample a labelled point cloud from ``truth`` as ``opts`` describes (see the module docstring)."""
    surf = _candidates(truth, opts, rng)
    st = stations(truth, opts)
    cand, ray_from = [], []
    for k, s in enumerate(st):
        seen = visible(surf, s, auto_pixel(surf.points, s), opts.depth_tolerance)
        cand.append(seen)
        ray_from.append(np.full(len(seen), k))
    cand, ray_from = np.concatenate(cand), np.concatenate(ray_from)
    keep = ~_missing(surf.points[cand], truth.positions[0], opts)
    cand, ray_from = cand[keep], ray_from[keep]
    if len(cand) > opts.points:
        pick = np.sort(rng.choice(len(cand), opts.points, replace=False))
        cand, ray_from = cand[pick], ray_from[pick]
    ray = surf.points[cand] - st[ray_from]
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    pts = (
        surf.points[cand] + rng.normal(0.0, opts.noise, len(cand))[:, None] * ray
        if opts.noise > 0
        else surf.points[cand]
    )
    return Scan(pts, surf.labels[cand], surf.branch_ids[cand].astype(np.int32), st)


def _candidates(truth: TreeTruth, opts: ScanOptions, rng: np.random.Generator) -> Surface:
    m = max(int(opts.oversample * opts.points), 1)
    if opts.leaf_off or truth.leaf_count == 0:
        return sample_wood(truth, m, rng)
    child = np.arange(1, truth.node_count)
    pa = truth.parent[child]
    wood_area = float((np.pi * (truth.radii[pa] + truth.radii[child]) * np.linalg.norm(
        truth.positions[child] - truth.positions[pa], axis=1)).sum())  # fmt: skip
    leaf_area = float((np.pi / 4 * LEAF_WIDTH_RATIO * truth.leaf_sizes**2).sum())
    m_leaf = int(round(m * leaf_area / (leaf_area + wood_area)))
    w, lf = sample_wood(truth, m - m_leaf, rng), sample_leaves(truth, m_leaf, rng)
    return Surface(*(np.concatenate([getattr(w, f), getattr(lf, f)]) for f in
                     ("points", "normals", "labels", "branch_ids", "two_sided")))  # fmt: skip


def _missing(pts: np.ndarray, root: np.ndarray, opts: ScanOptions) -> np.ndarray:
    """(M,) bool: points in the missing wedge or box."""
    out = np.zeros(len(pts), bool)
    if opts.missing_sector > 0:
        az = np.degrees(np.arctan2(pts[:, 1] - root[1], pts[:, 0] - root[0]))
        out |= np.mod(az - opts.missing_azimuth, 360.0) < opts.missing_sector
    if opts.missing_box is not None:
        b = np.asarray(opts.missing_box, dtype=np.float64)
        out |= np.all((pts >= b[:3]) & (pts <= b[3:]), axis=1)
    return out
