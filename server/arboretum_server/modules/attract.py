"""Attraction points (Sec. 4.2): rejection sampling inside the crown's SDF plus samples on its surface."""

from __future__ import annotations

import numpy as np

from .crown import Crown, crown_sdf, sample_crown_surface


def sample_attraction_points(
    crown: Crown, n_interior: int, n_surface: int, rng: np.random.Generator
) -> np.ndarray:
    """(n_interior + n_surface, 3) points: first inside the crown (SDF < 0), then on its surface."""
    lo, hi = crown.bounds
    found: list[np.ndarray] = []
    count = 0
    while count < n_interior:
        batch = lo + rng.random((max(2 * (n_interior - count), 256), 3)) * (hi - lo)
        inside = batch[crown_sdf(crown, batch) < 0]
        found.append(inside)
        count += len(inside)
    interior = np.concatenate(found)[:n_interior] if found else np.zeros((0, 3))
    return np.concatenate([interior, sample_crown_surface(crown, n_surface, rng)])
