"""Crown shapes: closed meshes -> a signed distance field on a grid (inside negative), trilinear lookup.

Inside/outside by ray parity along +X, one ray per grid row; each triangle is tested against the rows in
its (y, z) box only, in bounded blocks (memory does not grow with the triangle count).
Distance: exact (dense deterministic surface samples, cKDTree) within 3 cells of the surface, the
Euclidean distance transform of the inside mask further away (error under one cell). A union of meshes takes
the minimum of their fields, so overlapping parts are handled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from arboretum_library.errors import InputError


@dataclass(frozen=True)
class Crown:
    vertices: np.ndarray
    """(V, 3) float64 crown surface, world frame (Z up, metres); union of all parts."""
    faces: np.ndarray
    """(F, 3) int32 triangles of ``vertices``."""
    origin: np.ndarray
    """(3,) float64 world position of grid sample (0, 0, 0)."""
    spacing: float
    """Grid step in metres."""
    values: np.ndarray
    """(nx, ny, nz) float64 signed distance at the grid samples; negative inside."""

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned box of the crown surface."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])


def crown_sdf(crown: Crown, points: np.ndarray) -> np.ndarray:
    """Signed distance (N,) at ``points`` (N, 3) by trilinear lookup; beyond the grid, plus the gap."""
    from scipy.ndimage import map_coordinates

    p = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - crown.origin) / crown.spacing
    q = np.clip(p, 0, np.array(crown.values.shape) - 1)
    gap = np.sqrt(((p - q) ** 2).sum(axis=1)) * crown.spacing
    return map_coordinates(crown.values, q.T, order=1, mode="nearest", prefilter=False) + gap


def _row_ranges(lo, hi, q) -> tuple[np.ndarray, np.ndarray]:
    """First and one-past-last index of the sorted samples ``q`` within [lo, hi] (per triangle, padded)."""
    pad = 1e-9 * max(float(q[-1] - q[0]), 1.0) if len(q) else 0.0
    return np.searchsorted(q, lo - pad, side="left"), np.searchsorted(q, hi + pad, side="right")


def _blocks(counts: np.ndarray, block: int) -> list[np.ndarray]:
    """Consecutive triangle index blocks whose candidate-row counts sum to about ``block`` (at least one each)."""
    ends = np.searchsorted(np.cumsum(counts), np.arange(block, int(counts.sum()) + block, block), side="right")
    ends = np.unique(np.r_[np.clip(ends, 1, len(counts)), len(counts)])
    return [np.arange(s, e) for s, e in zip(np.r_[0, ends[:-1]], ends) if e > s]


def _inside_grid(vertices, faces, xs, ys, zs, block: int = 1 << 19) -> np.ndarray:
    """(nx, ny, nz) bool: ray parity along +X for every (y, z) grid row.

    Each triangle is tested only against the rows inside its (y, z) box, in blocks of about ``block``
    (triangle, row) pairs, so memory stays bounded (~100 MB) whatever the triangle count; a hit at x
    crosses every sample with xs > x, counted per row with a histogram and a cumulative sum.
    """
    tri = vertices[faces]
    qy, qz = ys + 1.234567e-7, zs + 7.654321e-8
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    den = (b[:, 1] - a[:, 1]) * (c[:, 2] - a[:, 2]) - (c[:, 1] - a[:, 1]) * (b[:, 2] - a[:, 2])
    ok = np.abs(den) > 1e-300
    a, b, c, den, tri = a[ok], b[ok], c[ok], den[ok], tri[ok]
    y0, y1 = _row_ranges(tri[:, :, 1].min(axis=1), tri[:, :, 1].max(axis=1), qy)
    z0, z1 = _row_ranges(tri[:, :, 2].min(axis=1), tri[:, :, 2].max(axis=1), qz)
    nzs = np.maximum(z1 - z0, 0)
    counts = np.maximum(y1 - y0, 0) * nzs
    nx, nz = len(xs), len(zs)
    hist = np.zeros(len(ys) * nz * (nx + 1), dtype=np.int64)
    for f in _blocks(counts, block) if counts.sum() else []:
        n = counts[f]
        f = np.repeat(f, n)
        r = np.arange(len(f)) - np.repeat(np.cumsum(n) - n, n)  # pair's place in its triangle's rows
        iy, iz = y0[f] + r // nzs[f], z0[f] + r % nzs[f]
        py, pz = qy[iy], qz[iz]
        A, B, C, D = a[f], b[f], c[f], den[f]
        l1 = ((B[:, 1] - py) * (C[:, 2] - pz) - (C[:, 1] - py) * (B[:, 2] - pz)) / D
        l2 = ((C[:, 1] - py) * (A[:, 2] - pz) - (A[:, 1] - py) * (C[:, 2] - pz)) / D
        l3 = 1 - l1 - l2
        hit = (l1 >= 0) & (l2 >= 0) & (l3 >= 0)
        x = l1[hit] * A[hit, 0] + l2[hit] * B[hit, 0] + l3[hit] * C[hit, 0]
        row = iy[hit] * nz + iz[hit]
        hist += np.bincount(row * (nx + 1) + np.searchsorted(xs, x, side="right"), minlength=len(hist))
    crossings = np.cumsum(hist.reshape(-1, nx + 1)[:, :nx], axis=1)
    return (crossings % 2 == 1).T.reshape(nx, len(ys), nz)


def _surface_samples(vertices, faces, step: float) -> np.ndarray:
    """Deterministic points (K, 3) on the triangles about ``step`` apart (barycentric grids)."""
    tri = vertices[faces]
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    m = np.maximum(1, np.ceil(edge / step)).astype(np.int64)
    out = [vertices]
    for k in np.unique(m):
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        w = np.stack([i[keep], j[keep]], axis=1) / k
        t = tri[m == k]
        out.append(
            (
                t[:, None, 0]
                + w[None, :, :1] * (t[:, None, 1] - t[:, None, 0])
                + w[None, :, 1:] * (t[:, None, 2] - t[:, None, 0])
            ).reshape(-1, 3)
        )
    return np.concatenate(out)


def _signed_grid(vertices, faces, xs, ys, zs, spacing) -> np.ndarray:
    """Signed distance on the grid: Euclidean distance transform far away, exact samples near the surface."""
    from scipy.ndimage import distance_transform_edt

    inside = _inside_grid(vertices, faces, xs, ys, zs)
    far = (
        np.where(inside, -distance_transform_edt(inside), distance_transform_edt(~inside)) * spacing
    )
    far = far - np.sign(far) * 0.5 * spacing
    near = np.abs(far) < 3 * spacing
    grid = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1)[near]
    tree = cKDTree(_surface_samples(vertices, faces, spacing / 4))
    dist, _ = tree.query(grid, distance_upper_bound=5 * spacing, workers=-1)
    out = far.copy()
    exact = np.where(np.isfinite(dist), dist, np.abs(far[near]))
    out[near] = np.where(inside[near], -exact, exact)
    return out


def _is_closed(faces: np.ndarray) -> bool:
    """True when every undirected edge of ``faces`` (F, 3) is used by exactly two triangles."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool((counts == 2).all())


def crown_from_meshes(meshes: list[tuple[np.ndarray, np.ndarray]], resolution: int = 64) -> Crown:
    """Crown of the union of closed meshes [(V, 3), (F, 3)], SDF grid of ``resolution`` cells on its longest axis."""
    if not meshes or any(len(f) < 4 for _, f in meshes):
        raise InputError("crown: needs at least one closed mesh with 4 or more triangles")
    for k, (_, f) in enumerate(meshes):
        if not _is_closed(np.asarray(f)):
            raise InputError(
                f"crown mesh {k}: not closed (every edge must be shared by exactly two triangles)"
            )
    verts = [np.asarray(v, dtype=np.float64) for v, _ in meshes]
    allv = np.concatenate(verts)
    lo, hi = allv.min(axis=0), allv.max(axis=0)
    spacing = float((hi - lo).max()) / resolution
    lo, hi = lo - 3 * spacing, hi + 3 * spacing
    xs, ys, zs = (np.arange(lo[k], hi[k] + spacing, spacing) for k in range(3))
    values = np.min(
        [_signed_grid(v, np.asarray(f), xs, ys, zs, spacing) for v, (_, f) in zip(verts, meshes)],
        axis=0,
    )
    offsets = np.cumsum([0] + [len(v) for v in verts[:-1]])
    faces = np.concatenate(
        [np.asarray(f, dtype=np.int32) + o for (_, f), o in zip(meshes, offsets)]
    )
    return Crown(allv, faces, lo, spacing, values)


def sample_crown_surface(crown: Crown, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points (n, 3) uniformly (by area) on the crown surface."""
    tri = crown.vertices[crown.faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    pick = rng.choice(len(tri), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    t = tri[pick]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
