"""Potential branching points (Sec. 4.3, Fig. 6): rays cast from the skeleton curve to the module surface.

Stations every Delta x along each spline; at each, ``n`` rays perpendicular to the tangent, evenly spread,
the fan turned by the junction angle alpha from one station to the next. Computed once per module in its
own frame, then moved with each placed instance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.geometry import polyline_lengths

from .moduleset import Module


@dataclass(frozen=True)
class BranchPoints:
    position: np.ndarray
    """(K, 3) float64 points on the surface (module or world frame)."""
    normal: np.ndarray
    """(K, 3) float64 unit direction of the cast ray (outward, perpendicular to the tangent)."""
    tangent: np.ndarray
    """(K, 3) float64 unit skeleton tangent transferred to the point."""
    radius: np.ndarray
    """(K,) float64 skeleton radius transferred to the point (scaled in world)."""


def _ray_hits(origin: np.ndarray, direction: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(R,) nearest positive hit distance of rays (R, 3) against triangles (F, 3, 3); inf when none."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(direction[:, None], e2[None])
    det = (p * e1[None]).sum(-1)
    good = np.abs(det) > 1e-12
    inv = np.where(good, 1.0 / np.where(good, det, 1.0), 0.0)
    s = origin[:, None] - tri[None, :, 0]
    u = (s * p).sum(-1) * inv
    q = np.cross(s, e1[None])
    v = (direction[:, None] * q).sum(-1) * inv
    t = (q * e2[None]).sum(-1) * inv
    hit = good & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
    return np.where(hit, t, np.inf).min(axis=1)


def _stations(
    module: Module, spacing: float, clearance: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (S, 3), tangents (S, 3) and radii (S,) every ``spacing`` along each spline."""
    sk = module.skeleton
    cs, ts, rs = [], [], []
    for s in np.unique(sk.spline):
        idx = np.flatnonzero(sk.spline == s)
        if len(idx) < 2:
            continue
        pts = sk.points[idx]
        arc = polyline_lengths(pts)
        at = np.arange(0.5 * spacing, arc[-1], spacing)
        c = np.stack([np.interp(at, arc, pts[:, k]) for k in range(3)], axis=1)
        t = np.stack([np.interp(at, arc, sk.tangent[idx, k]) for k in range(3)], axis=1)
        keep = np.linalg.norm(c, axis=1) >= clearance
        cs.append(c[keep]), ts.append(t[keep]), rs.append(np.interp(at, arc, sk.radius[idx])[keep])
    t = np.concatenate(ts)
    return np.concatenate(cs), t / np.linalg.norm(t, axis=1, keepdims=True), np.concatenate(rs)


def module_branch_points(
    module: Module,
    spacing_fraction: float,
    junctions: int,
    junction_angle_deg: float,
    clearance_fraction: float,
) -> BranchPoints:
    """Branching points of ``module`` in its own frame (Fig. 6)."""
    size = module.size
    c, t, r = _stations(module, spacing_fraction * size, clearance_fraction * size)
    helper = np.where(np.abs(t[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(t, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(t, e1)
    az = (
        np.radians(junction_angle_deg) * np.arange(len(c))[:, None]
        + 2 * np.pi * np.arange(junctions)[None] / junctions
    )
    d = (np.cos(az)[..., None] * e1[:, None] + np.sin(az)[..., None] * e2[:, None]).reshape(-1, 3)
    origin = np.repeat(c, junctions, axis=0)
    hit = _ray_hits(origin, d, module.vertices[module.faces])
    rr = np.repeat(r, junctions)
    dist = np.where(np.isfinite(hit) & (hit < 3 * rr + 1e-9), hit, rr)
    return BranchPoints(origin + dist[:, None] * d, d, np.repeat(t, junctions, axis=0), rr)


def place_branch_points(points: BranchPoints, T: np.ndarray) -> BranchPoints:
    """``points`` moved by the similarity ``T`` (4, 4) (uniform scale): positions, directions, radii."""
    A = T[:3, :3]
    s = float(np.cbrt(np.linalg.det(A)))
    R = A / s
    return BranchPoints(
        points.position @ A.T + T[:3, 3],
        points.normal @ R.T,
        points.tangent @ R.T,
        points.radius * s,
    )
