"""Global step (Sec. 4.3): pair attraction points with branching points by the cost of Eqs. 1-2.

Each attraction point meets its k nearest branching points (cKDTree). Eq. 1 picks a module and scale for
every pair at once (a numba kernel, compiled on first use and cached: one pass over pairs x modules);
Eq. 2 ranks the pairs. Paths that leave the crown are rejected by sphere tracing,
lazily: only an attraction point's current best pair is traced, and the next one only if it fails.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from arboretum_server.jitcache import njit

from .crown import Crown
from .trace import segments_stay_inside


@njit(cache=True)
def _running_argmin(t32, inv, s_lo, s_hi, radius, base_radius, gather):  # pragma: no cover - compiled
    """Eq. 1 per pair: the module minimising |clamp(t / size, s_l, cap) - 1|, in float32, ties keep the first.

    t32 (N,) float32 targets d_t, inv (M,) float32 1 / size, radius (Nb,) r_p and base_radius (M,) r_c
    float64, gather (N,) int64 branching point of each pair. cap = min(r_p / r_c, s_u) as float32 when
    r_p / r_c >= s_l, else -1e9 (infeasible). Returns the module (N,) and its cap (N,) float32: the same
    float32 operations, in the same order, as the numpy running argmin over modules it replaced.
    """
    n, one, lo = len(t32), np.float32(1.0), np.float32(s_lo)
    best = np.zeros(n, dtype=np.int64)
    cap_best = np.zeros(n, dtype=np.float32)
    for i in range(n):
        r, t, best_err = radius[gather[i]], t32[i], np.float32(np.inf)
        for m in range(len(inv)):
            ratio = r / base_radius[m]
            c = np.float32(min(ratio, s_hi)) if ratio >= s_lo else np.float32(-1e9)
            e = t * inv[m]
            e = e if e >= lo else lo
            e = e if e <= c else c
            e = abs(e - one)
            if e < best_err:
                best_err, best[i], cap_best[i] = e, m, c
    return best, cap_best


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
    t32, inv = target.astype(np.float32), (1.0 / size).astype(np.float32)
    best, cap_best = _running_argmin(
        t32.ravel(),
        inv,
        float(s_lo),
        float(s_hi),
        np.ascontiguousarray(parent_radius, dtype=np.float64),
        np.ascontiguousarray(base_radius, dtype=np.float64),
        gather.ravel().astype(np.int64),
    )
    best, cap_best = best.reshape(target.shape), cap_best.reshape(target.shape)
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
    widen: int = 4,
) -> np.ndarray:
    """(Na,) index of the chosen branching point for each attraction point (Na, 3), -1 for none.

    Attraction points whose ``k`` nearest branching points all fail the containment test (in a crown
    of disjoint parts the nearest ones often sit in a neighbouring part) are paired again among their
    ``widen`` x ``k`` nearest (ours; the paper pairs with the 25 closest only).
    """
    na = len(attract)
    if na == 0 or len(bp_pos) == 0:
        return np.full(na, -1)
    choice, blocked = _assign(attract, bp_pos, bp_radius, size, base_radius, crown, k, C, s_lo, s_hi, tol,
                              max_rounds)
    left = np.flatnonzero(blocked)
    if widen > 1 and len(left) and len(bp_pos) > k:
        choice[left] = _assign(attract[left], bp_pos, bp_radius, size, base_radius, crown, widen * k, C,
                               s_lo, s_hi, tol, max_rounds, skip=k)[0]
    return choice


def _assign(attract, bp_pos, bp_radius, size, base_radius, crown, k, C, s_lo, s_hi, tol, max_rounds,
            skip: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(choice (Na,), blocked (Na,) bool: every candidate tried failed the containment test), pairing
    each attraction point with its ``k`` nearest branching points but the first ``skip``."""
    na = len(attract)
    k = min(k, len(bp_pos))
    dt, j = cKDTree(bp_pos, leafsize=32, balanced_tree=False).query(
        attract, k=k, workers=-1
    )
    dt, j = dt.reshape(na, k), j.reshape(na, k)
    best_mod, s, feasible = choose_modules(dt, bp_radius, size, base_radius, s_lo, s_hi, gather=j)
    feasible[:, :skip] = False
    sigma = pair_cost(dt, size[best_mod] * s, feasible, C)
    order = np.argsort(sigma, axis=1, kind="stable")
    choice = np.full(na, -1)
    blocked = np.zeros(na, bool)
    todo = np.arange(na)
    for r in range(min(max_rounds, k)):
        cand = order[todo, r]
        alive = np.isfinite(sigma[todo, cand])
        todo, cand = todo[alive], cand[alive]
        if len(todo) == 0:
            break
        ok = segments_stay_inside(crown, bp_pos[j[todo, cand]], attract[todo], tol)
        choice[todo[ok]] = j[todo[ok], cand[ok]]
        blocked[todo[~ok]] = True
        blocked[todo[ok]] = False
        todo = todo[~ok]
    return choice, blocked & (choice < 0)
