"""Distance from points to a triangle mesh's surface, in numpy (no open3d).

The refinement's last resort for a buried lobe (``tunnel.depths``) measures how deep points lie inside other
lobes' hulls. It used the evaluation's ``evaluate.signed_distances``, open3d's ray casting, whose import
takes 2.1 s here: the first such insert in a service that had not imported open3d stalled that long (session
31). Hulls hold 100-500 triangles and the queries a few hundred points, so the closest point on every
triangle (Ericson, *Real-Time Collision Detection*, 5.1.5), in blocks of points, costs about a millisecond.
"""

from __future__ import annotations

import numpy as np

BLOCK = 256
"""Points per block of ``surface_distances``: a block holds (BLOCK, F, 3) arrays (about 3 MB each for
F = 500 triangles)."""


def surface_distances(vertices: np.ndarray, faces: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(M,) unsigned distance of each of ``q`` (M, 3) to the nearest triangle of the mesh (``vertices`` (V, 3),
    ``faces`` (F, 3)); inf for a mesh without triangles."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
    if not len(faces):
        return np.full(len(q), np.inf)
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    a, b, c = (tri[None, :, i] for i in range(3))
    out = np.full(len(q), np.inf)
    for s in range(0, len(q), BLOCK):
        p = q[s:s + BLOCK, None, :]
        d = np.sqrt(((p - _closest(p, a, b, c)) ** 2).sum(axis=2))
        out[s:s + BLOCK] = np.where(np.isnan(d), np.inf, d).min(axis=1)  # a triangle of no area: its edges count
    return out


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return (u * v).sum(axis=-1)


def _closest(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(M, F, 3): the point of each triangle (a, b, c) (1, F, 3) nearest each point ``p`` (M, 1, 3), by the
    Voronoi region of the triangle that ``p`` lies in (a vertex, an edge, or the face)."""
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):  # the regions that divide by 0 are not chosen
        on_ab = a + (d1 / (d1 - d3))[..., None] * ab
        on_ac = a + (d2 / (d2 - d6))[..., None] * ac
        on_bc = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[..., None] * (c - b)
        whole = va + vb + vc
        inner = a + (vb / whole)[..., None] * ab + (vc / whole)[..., None] * ac
    regions = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (vc <= 0) & (d1 >= 0) & (d3 <= 0),
               (d6 >= 0) & (d5 <= d6), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
               (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)]
    shape = np.broadcast_shapes(p.shape, a.shape)
    points = [np.broadcast_to(x, shape) for x in (a, b, on_ab, c, on_ac, on_bc)]
    return np.select([r[..., None] for r in regions], points, default=inner)
