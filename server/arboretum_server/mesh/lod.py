"""Levels of detail: fewer tube sides, coarser chains, and leaf cards merged into cluster cards."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.errors import InputError
from arboretum_server.grow.skeleton import Leaves

from .chains import Chains

MAX_LEVEL = 16
"""Coarsest level of detail the commands accept. On the grown coffee scan each level past 6 changes the
GLB by under 0.3 % and past 8 not at all (3 tube sides, chains down to their ends, one leaf cluster
per lobe: 40 cards for 40 lobes from LOD 6; ``cluster_leaves`` anchors each lobe's grid on its cards,
so at this level every lobe less than 65,536 median leaf lengths across is one card); the chain stride
2^(level-1) would overflow int64 from level 64 (``thin_chains`` now clamps it)."""
SIDES_RANGE = (3, 64)
"""Tube sides at LOD 0 the commands accept: a triangle is the least tube; 64 is eight times the default
and three times the finest we use (20 in the bench), far below the memory a sweep of that many sides
needs on a big tree (the sweep holds nodes × (sides + 1) × 3 float64 several times)."""


@dataclass(frozen=True)
class LodOptions:
    """Resolution of one level of detail."""

    sides: int = 8
    """Tube sides around a branch at LOD 0; halved per level, at least 3."""
    level: int = 0
    """0 = full detail; each level halves the sides and doubles the leaf cluster cell."""

    @property
    def tube_sides(self) -> int:
        return max(3, self.sides >> self.level)

    @property
    def chain_stride(self) -> int:
        """Keep every n-th inner chain vertex (1 at LOD 0 and 1, then 2, 4, ...)."""
        return 1 << max(self.level - 1, 0)


def thin_chains(chains: Chains, stride: int) -> Chains:
    """Drop inner chain vertices so every ``stride``-th one remains (ends always kept)."""
    if stride <= 1:
        return chains
    stride = min(stride, max(len(chains.nodes), 1))  # larger strides keep the same ends (and overflow int64)
    pos = np.arange(len(chains.nodes)) - chains.starts[chains.chain]
    last = chains.starts[chains.chain + 1] - 1
    keep = (pos % stride == 0) | (np.arange(len(chains.nodes)) == last)
    counts = np.bincount(chains.chain[keep], minlength=len(chains.starts) - 1)
    return Chains(chains.nodes[keep], np.r_[0, np.cumsum(counts)].astype(np.int64),
                  chains.chain[keep], chains.radius_node[keep])


def cluster_leaves(leaves: Leaves, cell: float) -> Leaves:
    """Merge the cards of each lobe inside one cubic cell of side ``cell`` into one card.

    Each lobe's grid starts at the lowest corner of its cards' centres, so a lobe whose cards span
    less than ``cell`` along every axis becomes exactly one card wherever it stands (a grid anchored
    at the world origin split the lobes straddling x = 0 or y = 0: 56 clusters for 40 lobes at LOD 16).
    The cluster card sits at the mean centre, faces the mean normal, and is sqrt(count) times the
    mean size, so the covered area stays about the same.
    """
    k = len(leaves.sizes)
    if k == 0 or cell <= 0:
        return leaves
    lobes, which = np.unique(leaves.lobe, return_inverse=True)
    corner = np.full((len(lobes), 3), np.inf)
    np.minimum.at(corner, which.ravel(), leaves.centres)
    ijk = np.floor((leaves.centres - corner[which.ravel()]) / cell).astype(np.int64)
    key = np.c_[leaves.lobe, ijk]
    _, group, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    g = len(counts)

    def mean(a: np.ndarray) -> np.ndarray:
        sums = [np.bincount(group, a[:, i], minlength=g) for i in range(a.shape[1])]
        return np.stack(sums, 1) / counts[:, None]

    normal = _unit(mean(leaves.normals))
    normal = np.where(np.linalg.norm(normal, axis=1, keepdims=True) > 0.5, normal, [0.0, 0.0, 1.0])
    axis = mean(leaves.axes)
    axis = axis - (axis * normal).sum(1, keepdims=True) * normal
    fallback = np.cross(normal, np.where(np.abs(normal[:, 2:3]) < 0.9, [0, 0, 1.0], [1.0, 0, 0]))
    axis = _unit(np.where(np.linalg.norm(axis, axis=1, keepdims=True) > 1e-6, axis, fallback))
    size = mean(leaves.sizes[:, None])[:, 0] * np.sqrt(counts)
    lobe = np.bincount(group, leaves.lobe, minlength=g) / counts
    return Leaves(mean(leaves.centres), normal, axis, size, np.rint(lobe).astype(np.int64))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def check_lod(level: int, sides: int | None = None) -> None:
    """``InputError`` unless ``--lod level`` (and ``--sides sides``) are ones the mesher takes."""
    if not 0 <= level <= MAX_LEVEL:
        raise InputError(f"--lod must be 0 (full detail) to {MAX_LEVEL} (coarsest), got {level}")
    lo, hi = SIDES_RANGE
    if sides is not None and not lo <= sides <= hi:
        raise InputError(f"--sides must be {lo} to {hi}, got {sides}")
