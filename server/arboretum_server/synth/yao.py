"""The Yao graph of a node set in 3D: each node links to its nearest neighbour in each sector.

The paper (Xu and Mould 2015, section 3.1.1) uses a 2D Yao-8 graph: 8 sectors of 45 degrees per node.
In 3D we cut the directions around a node into cones that tile the sphere, named by their count:

* ``8``  the octants (signs of dx, dy, dz): the paper's count, cones about 90 degrees wide;
* ``14`` nearest of the 6 face normals and 8 corner directions of a cube (default: 14 edges per node,
  cones about 55 degrees wide, paths noticeably straighter for the cost of 1.75x the edges);
* ``26`` nearest of the 26 directions to the neighbours of a cell in a 3x3x3 block.

Construction: one cKDTree query of the ``k`` nearest neighbours, then per node and sector the first
(nearest) neighbour in that sector, in the numba kernel ``kernels.yao_select``; ``sector_of`` is the
vectorised reference of its sector rule. A sector with no node among the ``k`` nearest gets no edge
(only at the volume's boundary for the default ``k``).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

SECTOR_COUNTS = (8, 14, 26)


@dataclass(frozen=True, eq=False)
class YaoGraph:
    """Directed graph with at most S out-edges per node (one per sector)."""

    points: np.ndarray
    """(N, 3) float64, metres: node positions."""
    neighbours: np.ndarray
    """(N, S) int32: out-neighbour per sector; the node itself where the sector is empty."""
    vectors: np.ndarray
    """(N, S, 3) float64: edge vectors (neighbour - node); zero where the sector is empty."""
    lengths: np.ndarray
    """(N, S) float64: edge lengths d_E (0 where the sector is empty)."""


def sector_axes(sectors: int) -> np.ndarray | None:
    """Cone axes (S, 3) for 14 or 26 sectors; None for the octants."""
    if sectors == 8:
        return None
    if sectors == 14:
        axes = [v for v in product((-1, 0, 1), repeat=3) if sum(map(abs, v)) in (1, 3)]
    elif sectors == 26:
        axes = [v for v in product((-1, 0, 1), repeat=3) if any(v)]
    else:
        raise ValueError(f"sectors must be one of {SECTOR_COUNTS}, got {sectors}")
    a = np.array(axes, dtype=np.float64)
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def sector_of(vectors: np.ndarray, sectors: int) -> np.ndarray:
    """Sector index (...) of each direction ``vectors`` (..., 3): the cone axis it is nearest to.

    Without a (..., S) dot-product table: for a cube direction using the m largest components (m = 1
    face, 2 edge, 3 corner) the best cosine is (sum of the m largest |v_i|) / sqrt(m), so picking the
    best m and the signs of those components names the nearest axis (index as in ``sector_axes``).
    """
    v = np.asarray(vectors)
    if sectors == 8:
        return ((v[..., 0] > 0) * 1 + (v[..., 1] > 0) * 2 + (v[..., 2] > 0) * 4).astype(np.int32)
    a = np.abs(v)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    rank = np.stack([(a1 > a0).astype(np.int8) + (a2 > a0), (a0 >= a1).astype(np.int8) + (a2 > a1),
                     (a0 >= a2).astype(np.int8) + (a1 >= a2)], axis=-1)  # fmt: skip
    total = a0 + a1 + a2
    big = np.maximum(np.maximum(a0, a1), a2)
    mid = total - big - np.minimum(np.minimum(a0, a1), a2)
    cos = np.stack([big, (big + mid) / np.sqrt(2.0), total / np.sqrt(3.0)], axis=-1)
    if sectors == 14:
        cos[..., 1] = -np.inf
    m = np.argmax(cos, axis=-1)[..., None] + 1
    direction = np.where(rank < m, np.where(v < 0, -1, 1), 0)
    code = ((direction + 1) * np.array([9, 3, 1])).sum(axis=-1)
    return _LOOKUP[sectors][code]


def _lookup(sectors: int) -> np.ndarray:
    table = np.full(27, -1, np.int32)
    for i, axis in enumerate(np.sign(sector_axes(sectors)).astype(int)):
        table[((axis + 1) * np.array([9, 3, 1])).sum()] = i
    return table


_LOOKUP = {s: _lookup(s) for s in (14, 26)}
_NONE = np.zeros(27, np.int32)  # the octants need no table


def _cell_size(points: np.ndarray) -> float:
    """Grid cell edge for the k-nearest search: the mean spacing, at least 1/256 of the extent."""
    span = np.ptp(points, axis=0)
    mean = (float(np.prod(span)) / len(points)) ** (1 / 3)
    return max(mean, float(span.max()) / 256, 1e-9)


def yao_graph(points: np.ndarray, sectors: int = 14, k: int = 24, workers: int = 2) -> YaoGraph:
    """Build the Yao graph of ``points`` (N, 3) with ``sectors`` cones, searching the ``k`` nearest."""
    if sectors not in SECTOR_COUNTS:
        raise ValueError(f"sectors must be one of {SECTOR_COUNTS}, got {sectors}")
    from .interrupt import interruptible
    from .kernels import knn, yao_select

    points = np.ascontiguousarray(points, dtype=np.float64)
    k = min(k, len(points) - 1)
    size, lookup = _cell_size(points), _LOOKUP.get(sectors, _NONE)
    with interruptible():
        nb = knn(points, k, size)
        out, vec, length = yao_select(points, nb, sectors, lookup)
    return YaoGraph(points, out, vec, length)
