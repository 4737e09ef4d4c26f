"""Branch radii by the pipe model: r^e at a vertex is the sum of r^e of everything it carries.

Every lobe carries a weight proportional to its point count (clipped to 0.2-5 times the mean), every
main-branch tip a weight of ``MAIN_TIP``; the weight at vertex k of a branch is its tip weight plus the
weights of the branches attached at vertices >= k. Radii are ``r0 (W / W_root)^(1/e)`` with r0 the
trunk radius measured at the base. So every radius is > 0 and a child is never thicker than its parent
at the joint (its weight there is part of the parent's).
"""

from __future__ import annotations

import numpy as np

MAIN_TIP = 0.5
"""Weight of a main-branch tip, in units of the mean lobe."""


def trunk_radius(points: np.ndarray, default: float = 0.01) -> float:
    """Trunk radius (0.8 m frame) from points (N, 3) in the slice 1-4 cm above the root at the origin."""
    sel = points[(points[:, 2] > 0.01) & (points[:, 2] < 0.04), :2]
    if len(sel) < 8:
        return default
    c = np.median(sel, axis=0)
    r = float(np.median(np.linalg.norm(sel - c, axis=1)))
    return float(np.clip(r, 0.002, 0.08))


def pipe_radii(lengths: list[int], parents: list[int], parent_vertex: list[int], tip_weight: list[float],
               r0: float, exponent: float = 2.0) -> list[np.ndarray]:
    """Radii (L_b,) for each branch b with ``lengths[b]`` vertices (parents before children)."""
    weights = [np.full(n, float(w)) for n, w in zip(lengths, tip_weight)]
    for b in range(len(lengths) - 1, -1, -1):
        p = parents[b]
        if p >= 0:
            weights[p][: parent_vertex[b] + 1] += weights[b][0]
    w0 = max(weights[0][0], 1e-12)
    return [np.maximum(r0 * (w / w0) ** (1.0 / exponent), 1e-6) for w in weights]


def lobe_weights(counts: np.ndarray) -> np.ndarray:
    """Tip weights (L,) of lobes holding ``counts`` (L,) points: count / mean, clipped to [0.2, 5]."""
    counts = np.asarray(counts, dtype=np.float64)
    if len(counts) == 0:
        return counts
    return np.clip(counts / max(counts.mean(), 1e-12), 0.2, 5.0)


def path_radii(owner: list[np.ndarray], r0: float) -> list[np.ndarray]:
    """Radii (L_b,) along each full path b from the root by the pipe model with the path tips alone: a
    vertex carried by c of the P paths (``owner[b]`` (L_b, 2): the (segment, vertex) each vertex is) has
    ``r0 sqrt(c / P)``. The main branches' wood before any lobe is known: the trunk ``r0``, one tip of eight
    main branches 0.35 ``r0``."""
    keys = [np.asarray(o, np.int64) for o in owner]
    if not keys:
        return []
    flat = np.concatenate(keys)
    _, inverse, counts = np.unique(flat, axis=0, return_inverse=True, return_counts=True)
    carried = counts[inverse.ravel()].astype(np.float64)
    r = r0 * np.sqrt(carried / len(keys))
    return np.split(r, np.cumsum([len(k) for k in keys])[:-1])
