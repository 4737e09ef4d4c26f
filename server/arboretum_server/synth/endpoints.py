"""Endpoint placement (Xu and Mould 2015, sections 3.2.2-3.2.4).

Early iterations draw endpoints from a user volume (``Volume``: a half-ellipsoid, an ellipsoid, a box
or an upright cylinder). Later iterations draw them from the surface of nodes exactly k hops (graph
edges) out from the tree so far, keeping its outermost fraction t when ordered by hops from the root.
The hanging and upward rules keep only endpoints lower (higher) than the source node their path leaves
the tree from; they are applied after the search, so more candidates are searched than kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

VOLUME_KINDS = ("half_ellipsoid", "ellipsoid", "box", "cylinder")
RULES = ("none", "hanging", "upward")


@dataclass(frozen=True)
class Volume:
    """An endpoint volume, metres, world frame (Z up)."""

    kind: str = "half_ellipsoid"
    """half_ellipsoid (the upper half, z >= centre z), ellipsoid, box or cylinder (axis along Z)."""
    centre: tuple[float, float, float] = (0.0, 0.0, 5.0)
    """Centre (3,); the flat face's centre for the half-ellipsoid."""
    radii: tuple[float, float, float] = (3.0, 3.0, 4.0)
    """Semi-axes (3,) (half extents for the box; radius, radius, half height for the cylinder)."""

    def __post_init__(self) -> None:
        if self.kind not in VOLUME_KINDS:
            raise ValueError(f"Volume.kind must be one of {VOLUME_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "centre", tuple(float(x) for x in self.centre))
        object.__setattr__(self, "radii", tuple(float(x) for x in self.radii))

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: which of ``points`` (N, 3) lie inside."""
        q = (points - np.array(self.centre)) / np.array(self.radii)
        if self.kind == "box":
            return np.all(np.abs(q) <= 1.0, axis=1)
        if self.kind == "cylinder":
            return (q[:, 0] ** 2 + q[:, 1] ** 2 <= 1.0) & (np.abs(q[:, 2]) <= 1.0)
        inside = (q**2).sum(axis=1) <= 1.0
        return inside & (q[:, 2] >= 0.0) if self.kind == "half_ellipsoid" else inside


def volume_candidates(points: np.ndarray, in_tree: np.ndarray, volume: Volume) -> np.ndarray:
    """Nodes inside ``volume`` and not yet in the tree."""
    return np.flatnonzero(volume.contains(points) & ~in_tree)


def surface_candidates(
    neighbours: np.ndarray, in_tree: np.ndarray, root_hops: np.ndarray, k: int, t: float,
    rng: np.random.Generator,
) -> np.ndarray:  # fmt: skip
    """The outermost fraction ``t`` (by hops from the root) of the nodes exactly ``k`` hops out.

    ``neighbours`` (N, S) are the out-edges; ``root_hops`` (N,) the hops from the root of the tree nodes.
    A surface node's hop count is that of the tree node its breadth-first search started from plus k;
    ties are broken at random.
    """
    visited = in_tree.copy()
    frontier = np.flatnonzero(in_tree)
    hops = root_hops[frontier]
    for _ in range(k):
        nb = neighbours[frontier].ravel()
        h = np.repeat(hops, neighbours.shape[1]) + 1
        fresh = ~visited[nb]
        nb, first = np.unique(nb[fresh], return_index=True)
        frontier, hops = nb, h[fresh][first]
        visited[frontier] = True
        if len(frontier) == 0:
            return frontier
    keep = math.ceil(t * len(frontier))
    order = np.lexsort((rng.random(len(frontier)), -hops))
    return frontier[order[:keep]]


def rule_ok(rule: str, z_end: np.ndarray, z_source: np.ndarray) -> np.ndarray:
    """(M,) bool: endpoints allowed by the hanging / upward rule given their sources' heights."""
    if rule == "hanging":
        return z_end < z_source
    if rule == "upward":
        return z_end > z_source
    return np.ones(len(z_end), bool)
