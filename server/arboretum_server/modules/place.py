"""Local step (Sec. 4.4): adjust branching points (Eq. 3), bias directions (4.4.2), pick the final module.

The final pick runs Eq. 1 on a target distance that blends the mean distance to the branching point's
attraction points with the distance to the crown surface along the branching direction (weight decaying
per layer), capped by the latter. A module is accepted only if its skeleton, placed, stays inside the
crown (within the tolerance); otherwise a smaller scale, then the next module, is tried.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .branching import BranchPoints
from .crown import Crown, crown_sdf
from .trace import ray_entry_exit


@dataclass(frozen=True)
class Placements:
    branch_point: np.ndarray
    """(P,) int index into the branching-point pool."""
    module: np.ndarray
    """(P,) int index into the branch-module table (not the module set)."""
    scale: np.ndarray
    """(P,) float64 uniform scale."""
    rotation: np.ndarray
    """(P, 3, 3) float64 world rotation of the module frame."""
    position: np.ndarray
    """(P, 3) float64 adjusted branching point p_new (the module base)."""
    direction: np.ndarray
    """(P, 3) float64 unit branching direction v (the module's +Z)."""
    entry: np.ndarray
    """(P,) float64 distance along ``direction`` before the branch enters the crown (0 if it starts in)."""


def unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-300)


def adjust_point(p, n, t, r, v) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3: rotate the branching points (B, 3) about the parent axis to face v; new points and normals."""
    u1 = unit(n - (n * t).sum(-1, keepdims=True) * t)
    c = p - r[:, None] * u1
    u2 = np.cross(t, u1)
    vp = v - (v * t).sum(-1, keepdims=True) * t
    phi = np.arctan2((vp * u2).sum(-1), (vp * u1).sum(-1))
    normal = np.cos(phi)[:, None] * u1 + np.sin(phi)[:, None] * u2
    return c + r[:, None] * normal, normal


def bias_direction(v, t, normal, lo: float, hi: float, beta: float) -> np.ndarray:
    """Sec. 4.4.2: move the angle between t and v a fraction ``beta`` of the way into [lo, hi] (radians)."""
    theta = np.arccos(np.clip((v * t).sum(-1), -1.0, 1.0))
    target = np.clip(theta, lo, hi)
    theta = theta + beta * (target - theta)
    w = v - (v * t).sum(-1, keepdims=True) * t
    w = np.where(np.linalg.norm(w, axis=-1, keepdims=True) > 1e-9, w, normal)
    return unit(np.cos(theta)[:, None] * t + np.sin(theta)[:, None] * unit(w))


def frames(direction: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(P, 3, 3) rotations taking +Z to ``direction`` (P, 3), turned by ``roll`` (P,) about it."""
    helper = np.where(np.abs(direction[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    x = unit(np.cross(helper, direction))
    y = np.cross(direction, x)
    xr = np.cos(roll)[:, None] * x + np.sin(roll)[:, None] * y
    yr = np.cross(direction, xr)
    return np.stack([xr, yr, direction], axis=-1)


def _fits(crown, skel, pos, R, scale, direction, entry, tol) -> np.ndarray:
    """(N,) bool: skeleton samples skel (N, S, 3) placed by (pos, R, scale) stay in the crown past ``entry``."""
    world = pos[:, None] + scale[:, None, None] * np.einsum("nij,nsj->nsi", R, skel)
    d = crown_sdf(crown, world.reshape(-1, 3)).reshape(world.shape[:2])
    along = ((world - pos[:, None]) * direction[:, None]).sum(-1)
    enters = (along >= entry[:, None]).any(axis=1) & (d <= 0).any(axis=1)  # else no branching point survives
    return ((d <= tol) | (along < entry[:, None])).all(axis=1) & enters


def choose_final(
    crown: Crown,
    target,
    parent_radius,
    size,
    base_radius,
    skel,
    pos,
    R,
    direction,
    entry,
    s_lo: float,
    s_hi: float,
    tol: float,
    shrink=(1.0, 0.8, 0.64),
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1 per placement with a containment check; module (P,) (-1 = skip) and scale (P,)."""
    ideal = target[:, None] / size
    ratio = parent_radius[:, None] / base_radius
    s = np.minimum(np.minimum(ideal, s_hi), ratio)
    ok = (ideal >= s_lo) & (ratio >= s_lo)
    err = np.where(ok, np.abs(s - 1.0), np.inf)
    order = np.argsort(err, axis=1, kind="stable")
    module, scale = np.full(len(target), -1), np.zeros(len(target))
    todo = np.arange(len(target))
    for rank in range(size.shape[0]):
        for f in shrink:
            m = order[todo, rank]
            sc = np.maximum(s[todo, m] * f, s_lo)
            live = np.isfinite(err[todo, m])
            good = live & _fits(
                crown, skel[m], pos[todo], R[todo], sc, direction[todo], entry[todo], tol
            )
            module[todo[good]], scale[todo[good]] = m[good], sc[good]
            todo = todo[~good & live]
            if len(todo) == 0:
                return module, scale
    return module, scale


def local_step(
    assign: np.ndarray,
    attract: np.ndarray,
    pool: BranchPoints,
    crown: Crown,
    size,
    base_radius,
    skel,
    weight: float,
    angles: tuple[float, float],
    beta: float,
    s_lo: float,
    s_hi: float,
    tol: float,
    rng: np.random.Generator,
) -> Placements:
    """Branches for every branching point chosen by at least one attraction point (Sec. 4.4)."""
    used = assign >= 0
    ids, inv = np.unique(assign[used], return_inverse=True)
    toward = attract[used] - pool.position[assign[used]]
    v = np.zeros((len(ids), 3))
    np.add.at(v, inv, unit(toward))
    p, n, t, r = pool.position[ids], pool.normal[ids], pool.tangent[ids], pool.radius[ids]
    v = np.where(np.linalg.norm(v, axis=1, keepdims=True) > 1e-9, unit(v), n)
    p_new, normal = adjust_point(p, n, t, r, v)
    if beta > 0:
        v = bias_direction(v, t, normal, angles[0], angles[1], beta)
    entry, exit_ = ray_entry_exit(crown, p_new, v, float(s_hi * size.max() * 1.5))
    mean_d = np.zeros(len(ids))
    np.add.at(mean_d, inv, np.linalg.norm(attract[used] - p_new[inv], axis=1))
    mean_d /= np.bincount(inv, minlength=len(ids))
    target = np.minimum((1 - weight) * mean_d + weight * exit_, exit_)
    R = frames(v, rng.uniform(0.0, 2 * np.pi, len(ids)))
    module, scale = choose_final(
        crown, target, r, size, base_radius, skel, p_new, R, v, entry, s_lo, s_hi, tol
    )
    k = module >= 0
    return Placements(ids[k], module[k], scale[k], R[k], p_new[k], v[k], entry[k])
