"""Leaf cards around the new twig nodes (VRTree 3.5, after Livny et al. 2010): seeded, facing out and up."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from arboretum_library.model import Lobe

from .hulls import HullIndex, inside
from .options import GrowOptions
from .radii import tip_heights
from .skeleton import Leaves

UP = np.array([0.0, 0.0, 1.0])
DEFAULT_SIZE = 1.2
"""Leaf card length in units of the growth radius D when ``leaf_size`` is None."""


def place_leaves(positions: np.ndarray, parents: np.ndarray, lobe: np.ndarray,
                 lobes: Sequence[Lobe], index: HullIndex, opts: GrowOptions, step: float,
                 rng: np.random.Generator) -> Leaves:
    """Cards on twig nodes within ``leaf_tip_depth`` hops of a tip, kept when their attachment lies in
    the lobe hull.

    Each eligible node gets Poisson(leaf_density) cards (denser twigs make more eligible nodes). A card faces its lobe's outward
    direction tilted up (out + 0.6 up) plus Gaussian jitter of ``leaf_jitter``; its stem sits at the node
    and its length points along the twig (parent -> node) bent towards the facing plane, with jitter.
    A card is kept when the centre a default-size card (``DEFAULT_SIZE`` D, times the card's own random
    factor) would have lies inside its hull: at the default size that is the card's centre; a
    ``leaf_size`` makes the same cards longer or shorter, never fewer (testing the centre of a 16 times
    longer card dropped 94 % of them). Big cards therefore overhang the hull by up to their length.
    """
    base = DEFAULT_SIZE * step
    size = opts.leaf_size if opts.leaf_size is not None else base
    twig = np.flatnonzero((lobe >= 0) & (parents >= 0))
    height = tip_heights(parents)
    node = twig[height[twig] <= opts.leaf_tip_depth]
    counts = rng.poisson(opts.leaf_density, len(node))
    node = np.repeat(node, counts)
    k = len(node)
    centre_of = np.array([lb.centre for lb in lobes]).reshape(-1, 3)
    out = _unit(positions[node] - centre_of[lobe[node]]) if k else np.zeros((0, 3))
    normal = _unit(out + 0.6 * UP + opts.leaf_jitter * rng.normal(size=(k, 3)))
    along = _unit(positions[node] - positions[parents[node]]) + 0.8 * rng.normal(size=(k, 3))
    axis = along - (along * normal).sum(1, keepdims=True) * normal
    axis = _unit(np.where(np.linalg.norm(axis, axis=1, keepdims=True) < 1e-6, _any_perp(normal), axis))
    factor = rng.uniform(0.8, 1.2, k)
    sizes = size * factor
    centres = positions[node] + axis * sizes[:, None] / 2
    probe = positions[node] + axis * (base * factor)[:, None] / 2
    keep = inside(index, probe, lobe[node])
    return Leaves(centres[keep], normal[keep], axis[keep], sizes[keep], lobe[node][keep])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def _any_perp(n: np.ndarray) -> np.ndarray:
    """A vector perpendicular to each row of ``n`` (K, 3)."""
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, UP, np.array([1.0, 0.0, 0.0]))
    return np.cross(n, ref)
