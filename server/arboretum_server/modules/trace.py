"""Batched sphere tracing through the crown SDF (Hart 1996), over many segments or rays at once."""

from __future__ import annotations

import numpy as np

from .crown import Crown, crown_sdf


def segments_stay_inside(
    crown: Crown, start: np.ndarray, end: np.ndarray, tol: float, max_steps: int = 200
) -> np.ndarray:
    """(N,) bool: segment start -> end (N, 3) never leaves the crown by more than ``tol`` once it is in.

    A segment that starts outside (a trunk below the crown) may first enter; after that it must stay.
    """
    seg = end - start
    length = np.linalg.norm(seg, axis=1)
    d0, d1 = crown_sdf(crown, start), crown_sdf(crown, end)
    quick = (d0 < 0) & (d1 < 0) & (length <= -d0 - d1)  # the two end balls cover the segment
    valid = quick.copy()
    todo = np.flatnonzero(~quick & (d1 <= tol))
    t = np.zeros(len(todo))
    entered = d0[todo] <= tol
    min_step = 0.5 * crown.spacing
    for _ in range(max_steps):
        if len(todo) == 0:
            break
        x = start[todo] + t[:, None] * seg[todo]
        d = crown_sdf(crown, x)
        bad = entered & (d > tol)
        entered |= d <= 0
        t = t + np.maximum(np.abs(d), min_step) / np.maximum(length[todo], 1e-300)
        done = t >= 1.0
        valid[todo[done & ~bad]] = True
        keep = ~done & ~bad
        todo, t, entered = todo[keep], t[keep], entered[keep]
    return valid


def ray_entry_exit(
    crown: Crown, origin: np.ndarray, direction: np.ndarray, max_dist: float, max_steps: int = 200
) -> tuple[np.ndarray, np.ndarray]:
    """Distances (N,), (N,) along unit rays (N, 3) from ``origin`` (N, 3) to where they enter and leave the crown.

    A ray starting inside enters at 0. Both are capped at ``max_dist``; a ray that never enters gets
    entry = exit = max_dist.
    """
    n = len(origin)
    t = np.zeros(n)
    exit_ = np.full(n, float(max_dist))
    entry = np.full(n, float(max_dist))
    inside0 = crown_sdf(crown, origin) <= 0
    entry[inside0] = 0.0
    entered = inside0.copy()
    todo = np.arange(n)
    min_step = 0.25 * crown.spacing
    for _ in range(max_steps):
        if len(todo) == 0:
            break
        d = crown_sdf(crown, origin[todo] + t[todo, None] * direction[todo])
        leaving = entered[todo] & (d > 0)
        exit_[todo[leaving]] = t[todo[leaving]]
        now_in = ~entered[todo] & (d <= 0)
        entry[todo[now_in]] = t[todo[now_in]]
        entered[todo] |= d <= 0
        t[todo] += np.maximum(np.abs(d), min_step)
        todo = todo[~leaving & (t[todo] < max_dist)]
    return np.minimum(entry, max_dist), np.minimum(exit_, max_dist)
