"""Pipe-model radii (Shinozaki; Leonardo's rule) over a tree graph whose parents precede children."""

from __future__ import annotations

import numpy as np


def depths(parents: np.ndarray) -> np.ndarray:
    """(N,) int64 hop count from each node to its root, for ``parents`` (N,) (-1 = root)."""
    parents = np.asarray(parents, np.int64)
    depth = np.zeros(len(parents), np.int64)
    anc = parents.copy()
    while True:
        has = anc >= 0
        if not has.any():
            return depth
        depth += has
        anc[has] = parents[anc[has]]


def pipe_radii(parents: np.ndarray, tip_radius: np.ndarray, exponent: float = 2.0) -> np.ndarray:
    """Radii (N,) with r_parent^e = Σ r_child^e, starting from ``tip_radius`` (N,) at the leaves.

    ``tip_radius`` is only read at nodes without children. Since every term of the sum is positive, a
    child is never thicker than its parent.
    """
    parents = np.asarray(parents, np.int64)
    n = len(parents)
    has_child = np.zeros(n, bool)
    has_child[parents[parents >= 0]] = True
    acc = np.where(has_child, 0.0, np.asarray(tip_radius, np.float64) ** exponent)
    depth = depths(parents)
    order = np.argsort(-depth, kind="stable")
    bounds = np.flatnonzero(np.diff(depth[order])) + 1
    for level in np.split(order, bounds):
        level = level[parents[level] >= 0]
        np.add.at(acc, parents[level], acc[level])
    return acc ** (1.0 / exponent)


def tip_heights(parents: np.ndarray) -> np.ndarray:
    """(N,) int64: the most hops from each node down to a tip below it (0 at tips)."""
    parents = np.asarray(parents, np.int64)
    height = np.zeros(len(parents), np.int64)
    depth = depths(parents)
    order = np.argsort(-depth, kind="stable")
    bounds = np.flatnonzero(np.diff(depth[order])) + 1
    for level in np.split(order, bounds):
        level = level[parents[level] >= 0]
        np.maximum.at(height, parents[level], height[level] + 1)
    return height


def lobe_twig_radii(parents: np.ndarray, lobe: np.ndarray, branch_radii: np.ndarray, tip_radius: float,
                    min_radius: float, exponent: float = 2.0) -> np.ndarray:
    """Radii (N,) of a tree whose first ``len(branch_radii)`` nodes are HBL branches (kept as given).

    The twigs (the other nodes, ``lobe`` (N,) >= 0) get pipe-model radii within their lobe from
    ``tip_radius`` at their tips. Then each lobe's twigs are scaled by one factor so that the pipe sum
    of its twig roots (the lobe's load on its bud) does not exceed the bud's branch radius, and
    floored at ``min(min_radius, bud radius)``. Both maps are monotone, so a twig is never thicker
    than its parent twig, and a twig root never thicker than its bud.
    """
    parents = np.asarray(parents, np.int64)
    n0, n = len(branch_radii), len(parents)
    tips = np.full(n, float(tip_radius))
    tips[:n0] = 0.0  # HBL tips carry nothing: only twig load is summed
    r = pipe_radii(parents, tips, exponent)
    twig = np.arange(n0, n)
    out = np.concatenate([np.asarray(branch_radii, np.float64), r[n0:]])
    if n == n0:
        return out
    roots = twig[parents[twig] < n0]
    n_lobes = int(lobe[twig].max()) + 1
    load = np.bincount(lobe[roots], weights=r[roots] ** exponent, minlength=n_lobes) ** (1.0 / exponent)
    bud = np.zeros(n_lobes)
    bud[lobe[roots]] = out[parents[roots]]
    scale = np.minimum(1.0, bud / np.maximum(load, 1e-300))
    low = np.minimum(float(min_radius), bud)
    lt = lobe[twig]
    out[n0:] = np.maximum(scale[lt] * r[twig], low[lt])
    return out
