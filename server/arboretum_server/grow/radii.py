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
