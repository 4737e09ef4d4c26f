"""Global step (Sec. 4.3): pair attraction points with branching points by the cost of Eqs. 1-2.

Each attraction point meets its k nearest branching points (cKDTree). Eq. 1 picks a module and scale for
every pair at once; Eq. 2 ranks the pairs. Paths that leave the crown are rejected by sphere tracing,
lazily: only an attraction point's current best pair is traced, and the next one only if it fails.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .crown import Crown
from .trace import segments_stay_inside


def choose_modules(
    target: np.ndarray,
    parent_radius: np.ndarray,
    size: np.ndarray,
    base_radius: np.ndarray,
    s_lo: float,
    s_hi: float,
    gather: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 1 for targets d_t (...,) and parent radii r_p over modules with size (M,) and r_c (M,).

    ``parent_radius`` has the shape of ``target``, or is per branching point (Nb,) with ``gather`` (...,)
    indexing it (cheaper: the radius caps are then computed once per branching point).
    Returns the best module (...,), its scale s(M_b) (...,) and a feasibility mask (...,): a module is
    feasible when r_p / r_c >= s_l, so the clamp keeps both the scale and the radius constraint.
    """
    if gather is None:
        gather, parent_radius = np.arange(parent_radius.size).reshape(target.shape), parent_radius.ravel()
    ratio = parent_radius[None, :] / base_radius[:, None]  # (M, Nb): one contiguous row per module
    # infeasible modules get a huge negative cap: their clamped scale, and so their error, is enormous
    cap = np.where(ratio >= s_lo, np.minimum(ratio, s_hi), -1e9).astype(np.float32)
    t32, inv = target.astype(np.float32), (1.0 / size).astype(np.float32)
    best = np.zeros(target.shape, dtype=np.int64)
    best_err = np.full(target.shape, np.inf, dtype=np.float32)
    err = np.zeros(target.shape, dtype=np.float32)
    for m in range(len(size)):  # running argmin over modules (ties keep the first, as argmin does)
        np.multiply(t32, inv[m], out=err)
        np.maximum(err, np.float32(s_lo), out=err)
        np.minimum(err, cap[m][gather], out=err)
        err -= np.float32(1.0)
        np.abs(err, out=err)
        best[err < best_err] = m
        np.minimum(best_err, err, out=best_err)
    cap_best = cap[best, gather]
    pick = np.minimum(np.maximum(t32 * inv[best], np.float32(s_lo)), cap_best)
    return best, pick.astype(np.float64), cap_best >= s_lo


def pair_cost(dt: np.ndarray, length: np.ndarray, feasible: np.ndarray, C: float) -> np.ndarray:
    """Eq. 2: sigma (Na, k) from target distances d_t (Na, k) and scaled lengths size(M_b) s(M_b) (Na, k)."""
    dt_safe = np.maximum(dt, 1e-12)
    dc = np.where(feasible, dt, np.inf).min(axis=1, keepdims=True)
    dc = np.where(np.isfinite(dc), dc, 0.0)
    lam1 = dc / (dc + C)
    sigma = lam1 * np.abs(length / dt_safe - 1.0) + (1.0 - lam1) * dt / (dt + C)
    return np.where(feasible, sigma, np.inf)


def assign_attraction(
    attract: np.ndarray,
    bp_pos: np.ndarray,
    bp_radius: np.ndarray,
    size: np.ndarray,
    base_radius: np.ndarray,
    crown: Crown,
    *,
    k: int,
    C: float,
    s_lo: float,
    s_hi: float,
    tol: float,
    max_rounds: int = 8,
) -> np.ndarray:
    """(Na,) index of the chosen branching point for each attraction point (Na, 3), -1 for none."""
    na = len(attract)
    if na == 0 or len(bp_pos) == 0:
        return np.full(na, -1)
    k = min(k, len(bp_pos))
    dt, j = cKDTree(bp_pos, balanced_tree=False).query(attract, k=k, workers=-1)
    dt, j = dt.reshape(na, k), j.reshape(na, k)
    best_mod, s, feasible = choose_modules(dt, bp_radius, size, base_radius, s_lo, s_hi, gather=j)
    sigma = pair_cost(dt, size[best_mod] * s, feasible, C)
    order = np.argsort(sigma, axis=1, kind="stable")
    choice = np.full(na, -1)
    todo = np.arange(na)
    for r in range(min(max_rounds, k)):
        cand = order[todo, r]
        alive = np.isfinite(sigma[todo, cand])
        todo, cand = todo[alive], cand[alive]
        if len(todo) == 0:
            break
        ok = segments_stay_inside(crown, bp_pos[j[todo, cand]], attract[todo], tol)
        choice[todo[ok]] = j[todo[ok], cand[ok]]
        todo = todo[~ok]
    return choice
