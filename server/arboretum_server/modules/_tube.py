"""A small private tube sweep: a tree of limbs -> one closed, connected triangle mesh.

Limbs meet only at their ends: a junction joins the last ring of a limb with the first rings of its
children through the convex hull of those rings (faces lying in one ring's plane are dropped). Bases and
tips get fan caps. It stays apart from ``arboretum_server.mesh.tubes`` on purpose: that mesher sweeps
each chain as its own closed tube, while a module must be one connected mesh for the geodesic skeleton
of Appendix A (``modules.skeleton``) to reach every branch from the base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from arboretum_library.geometry import polyline_lengths


@dataclass(frozen=True)
class Limb:
    points: np.ndarray
    """(P, 3) float64 centre line, module frame; a child's first point is its parent's last point."""
    radii: np.ndarray
    """(P,) float64 tube radius at each point."""
    parent: int
    """Index of the parent limb, -1 for the root limb."""


def _frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit tangents (P, 3) and parallel-transported normals/binormals (P, 3) along ``points``."""
    d = np.gradient(points, axis=0)
    t = d / np.linalg.norm(d, axis=1, keepdims=True)
    helper = np.array([1.0, 0.0, 0.0]) if abs(t[0, 0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    n = np.cross(t[0], helper)
    normals = [n / np.linalg.norm(n)]
    for k in range(1, len(t)):
        n = normals[-1] - np.dot(normals[-1], t[k]) * t[k]
        normals.append(n / np.linalg.norm(n))
    nrm = np.array(normals)
    return t, nrm, np.cross(t, nrm)


def _trim(limb: Limb, start: float, end: float) -> tuple[np.ndarray, np.ndarray]:
    """Points/radii of ``limb`` between arc lengths ``start`` and ``L - end`` (resampled ends)."""
    s = polyline_lengths(limb.points)
    keep = (s > start) & (s < s[-1] - end)
    ts = np.concatenate([[start], s[keep], [s[-1] - end]])
    pts = np.stack([np.interp(ts, s, limb.points[:, k]) for k in range(3)], axis=1)
    return pts, np.interp(ts, s, limb.radii)


def _junction_offsets(limbs: list[Limb], children: dict[int, list[int]]) -> dict[int, float]:
    """Arc length at which each child's first ring sits, so every ring's plane supports the hull."""
    out: dict[int, float] = {}
    for i, kids in children.items():
        if not kids:
            continue
        r_j = limbs[i].radii[-1]
        d_p = limbs[i].points[-1] - limbs[i].points[-2]
        dirs = [d_p / np.linalg.norm(d_p)]
        for k in kids:
            d = limbs[k].points[1] - limbs[k].points[0]
            dirs.append(d / np.linalg.norm(d))
        radii = [r_j] + [limbs[k].radii[0] for k in kids]
        off = [-0.8 * r_j] + [max(1.2 * r_j, 2.5 * limbs[k].radii[0]) for k in kids]
        for _ in range(50):
            for a in range(1, len(dirs)):
                for b in range(len(dirs)):
                    if a != b:
                        cos = float(np.clip(np.dot(dirs[a], dirs[b]), -1, 1))
                        need = off[b] * cos + radii[b] * np.sqrt(1 - cos * cos) + 0.3 * radii[a]
                        off[a] = max(off[a], need)
        out.update({k: off[n + 1] for n, k in enumerate(kids)})
    return out


def _junction_faces(verts: np.ndarray, rings: list[np.ndarray]) -> np.ndarray:
    """Outward faces (F, 3) of the hull over the vertex ids in ``rings``, minus in-ring faces."""
    ids = np.concatenate(rings)
    ring_of = np.concatenate([np.full(len(r), k) for k, r in enumerate(rings)])
    hull = ConvexHull(verts[ids])
    simp = hull.simplices
    same = (ring_of[simp[:, 0]] == ring_of[simp[:, 1]]) & (
        ring_of[simp[:, 1]] == ring_of[simp[:, 2]]
    )
    simp, eq = simp[~same], hull.equations[~same]
    p = verts[ids[simp]]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = (nrm * eq[:, :3]).sum(axis=1) < 0
    simp[flip] = simp[flip][:, ::-1]
    return ids[simp]


def sweep_limbs(limbs: list[Limb], sides: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Closed mesh of a limb tree: vertices (V, 3) float64 and outward faces (F, 3) int32."""
    children = {i: [j for j, c in enumerate(limbs) if c.parent == i] for i in range(len(limbs))}
    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    first_ring: dict[int, np.ndarray] = {}
    last_ring: dict[int, np.ndarray] = {}
    count = 0
    ang = 2 * np.pi * np.arange(sides) / sides
    offsets = _junction_offsets(limbs, children)
    for i, limb in enumerate(limbs):
        start = offsets.get(i, 0.0)
        end = 0.8 * limb.radii[-1] if children[i] else 0.0
        pts, rad = _trim(limb, start, end)
        t, n, b = _frames(pts)
        ring = pts[:, None] + rad[:, None, None] * (
            np.cos(ang)[None, :, None] * n[:, None] + np.sin(ang)[None, :, None] * b[:, None]
        )
        idx = count + np.arange(len(pts) * sides).reshape(len(pts), sides)
        verts.append(ring.reshape(-1, 3))
        count += len(pts) * sides
        a, c = idx[:-1], np.roll(idx[:-1], -1, axis=1)
        d, e = idx[1:], np.roll(idx[1:], -1, axis=1)
        faces.append(np.stack([a, c, e], axis=-1).reshape(-1, 3))
        faces.append(np.stack([a, e, d], axis=-1).reshape(-1, 3))
        first_ring[i], last_ring[i] = idx[0], idx[-1]
        for ring_ids, centre, capped, is_base in (
            (idx[0], pts[0], limb.parent < 0, True),
            (idx[-1], pts[-1], not children[i], False),
        ):
            if not capped:
                continue
            verts.append(centre[None])
            fan = np.stack([np.full(sides, count), ring_ids, np.roll(ring_ids, -1)], axis=1)
            faces.append(fan[:, [0, 2, 1]] if is_base else fan)
            count += 1
    v = np.concatenate(verts)
    for i, kids in children.items():
        if kids:
            faces.append(_junction_faces(v, [last_ring[i]] + [first_ring[k] for k in kids]))
    return v, np.concatenate(faces).astype(np.int32)
