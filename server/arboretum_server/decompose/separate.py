"""Leaf/wood separation: a local-dimension heuristic in the spirit of Guo et al. (VRTree section 3.4).

At a scale of a few centimetres (0.8 m frame) branches are curves or cylinder walls (dimension 1-2)
while foliage fills space (dimension near 3). We estimate a box-counting dimension for every point from
the growth of its neighbour count between two box sizes, d = log(n(3a) / n(a)) / log 3 (n counted over
3x3x3 cells of 0.8 and 2.4 cm: boxes a = 2.4 cm and 3a = 7.2 cm across), average it over the point and
its nearest neighbours, and call points above ``threshold`` foliage. Labels given with the input replace
the heuristic.

What it finds (docs/decomposition.md, Limitations): the real leaf-off scans come out 95-98 % wood and
the real leaf-on ones 63-64 %; the synthetic trees' leaf cards mostly read as wood and their dense twig
tufts and whorl hubs as foliage (the leaf-off harmonic pine 58-65 % wood), so on the synthetic trees the
guess is no better than chance. What the pipeline needs from it holds either way: leaf edges cost more
for the main branches, and the lobes take the crown off the main branches whatever the labels say.
"""

from __future__ import annotations

import numpy as np

from arboretum_library.model import LEAF, WOOD

from .grid import box_counts

CELL = 0.008
"""Small cell (0.8 m frame); the large one is three times bigger."""
CHUNK = 1 << 16
"""``local_dimension`` averages this many points' neighbourhoods at a time (a (CHUNK, k + 1) gather
instead of an (N, k + 1) one and its index copy: 272 MB on a million points)."""
LEAF_DIMENSION = 2.1
"""Default threshold: smoothed local dimension above this is foliage."""


def local_dimension(points: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Smoothed local dimension (N,) of ``points`` (N, 3), averaged over ``neighbours`` (N, k) indices."""
    n1 = box_counts(points, CELL)
    n2 = box_counts(points, 3 * CELL)
    d = np.log(n2 / np.maximum(n1, 1)) / np.log(3.0)
    out = np.zeros(len(points))
    for s in range(0, len(points), CHUNK):
        own = np.arange(s, min(s + CHUNK, len(points)))
        out[own] = d[np.concatenate([own[:, None], neighbours[own]], axis=1)].mean(axis=1)
    return out


def separate(points: np.ndarray, neighbours: np.ndarray, threshold: float = LEAF_DIMENSION) -> np.ndarray:
    """Labels (N,) uint8: LEAF where the smoothed local dimension exceeds ``threshold``, else WOOD."""
    dim = local_dimension(points, neighbours)
    return np.where(dim > threshold, LEAF, WOOD).astype(np.uint8)
