"""Attraction points of every lobe: its hull vertices (VRTree 3.5) plus interior samples at a density."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from arboretum_library.model import Lobe

from .hulls import HullIndex, build_index, mesh_volume, sample_inside
from .options import GrowOptions


@dataclass(frozen=True, eq=False)
class Attraction:
    """Attraction points of all lobes, lobe after lobe."""

    points: np.ndarray
    """(P, 3) float64, metres, world frame."""
    lobe: np.ndarray
    """(P,) int64: the lobe each point belongs to (points of a lobe are contiguous)."""
    starts: np.ndarray
    """(L + 1,) int64: points of lobe l are ``points[starts[l]:starts[l + 1]]``."""
    index: HullIndex
    """Point-in-hull index of the lobes' hulls (hull l is lobe l)."""


def equivalent_radius(lobe: Lobe) -> float:
    """Radius (m) of the sphere with the volume of the lobe's hull."""
    return float((3.0 * mesh_volume(lobe.hull_vertices, lobe.hull_faces) / (4.0 * np.pi)) ** (1 / 3))


def default_step(lobes: Sequence[Lobe]) -> float:
    """The growth radius D used when the options give none: 1/6 of the median lobe equivalent radius."""
    radii = [equivalent_radius(lb) for lb in lobes]
    return max(float(np.median(radii)) / 6.0, 1e-4) if radii else 0.05


def attraction_points(lobes: Sequence[Lobe], opts: GrowOptions, step: float,
                      rng: np.random.Generator) -> Attraction:
    """Hull vertices plus ``attraction_density × density × volume / step³`` interior samples per lobe."""
    index = build_index([(lb.hull_vertices, lb.hull_faces) for lb in lobes])
    mult = np.array([opts.lobe_multiplier(i) for i in range(len(lobes))])
    cap = np.array([max(opts.max_points_per_lobe - len(lb.hull_vertices), 0) for lb in lobes])
    volume = np.array([mesh_volume(lb.hull_vertices, lb.hull_faces) for lb in lobes])
    n = np.minimum(np.round(opts.attraction_density * mult * volume / step**3), cap).astype(np.int64)
    interior = sample_inside(index, n, rng)
    chunks = [np.concatenate([lb.hull_vertices, pts]) if m > 0 else np.zeros((0, 3))
              for lb, pts, m in zip(lobes, interior, mult)]
    counts = np.array([len(c) for c in chunks], np.int64)
    points = np.concatenate(chunks) if chunks else np.zeros((0, 3))
    lobe = np.repeat(np.arange(len(lobes)), counts)
    return Attraction(points, lobe, np.r_[0, np.cumsum(counts)].astype(np.int64), index)
