"""Branch similarity with 3D shape contexts and optimal assignment (VRTree section 3.4, after [BMP02]).

Each branch is resampled to ``n`` vertices. A vertex's shape context is the histogram of the vectors to
the branch's other vertices in log-radius (distances normalised by the branch's mean pairwise distance,
log-spaced between 1/8 and 2 as in Belongie et al.), azimuth and elevation bins. The cost of matching
two vertices is the chi-square distance of their histograms; the similarity cost of two branches is the
total cost sum_ij C[i, j] X[i, j] of the optimal assignment X (Hungarian algorithm, scipy's
linear_sum_assignment). Lower is more similar. Histograms and chi-square matrices are computed for many
branch pairs at once.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from arboretum_library.geometry import resample_polyline

R_INNER, R_OUTER = 0.125, 2.0


def shape_contexts(branches: np.ndarray, bins: tuple[int, int, int] = (5, 6, 4)) -> np.ndarray:
    """Normalised histograms (B, n, nr * na * ne) of resampled branches ``branches`` (B, n, 3)."""
    nr, na, ne = bins
    b, n, _ = branches.shape
    v = branches[:, None, :, :] - branches[:, :, None, :]  # (B, n, n, 3): from vertex i to j
    r = np.linalg.norm(v, axis=3)
    off = ~np.eye(n, dtype=bool)[None]
    mean = np.maximum((r * off).sum(axis=(1, 2)) / (n * (n - 1)), 1e-12)
    rn = r / mean[:, None, None]
    edges = np.geomspace(R_INNER, R_OUTER, nr + 1)
    ri = np.clip(np.searchsorted(edges, rn) - 1, 0, nr - 1)
    az = np.arctan2(v[..., 1], v[..., 0])
    ai = np.clip(((az + np.pi) / (2 * np.pi) * na).astype(int), 0, na - 1)
    el = np.arcsin(np.clip(v[..., 2] / np.maximum(r, 1e-12), -1.0, 1.0))
    ei = np.clip(((el + np.pi / 2) / np.pi * ne).astype(int), 0, ne - 1)
    flat = (ri * na + ai) * ne + ei
    hist = np.zeros((b, n, nr * na * ne))
    bi, ii, _ = np.nonzero(np.broadcast_to(off, (b, n, n)))
    np.add.at(hist, (bi, ii, flat[off.repeat(b, axis=0)]), 1.0)
    return hist / (n - 1)


def chi_square(h1: np.ndarray, h2: np.ndarray) -> np.ndarray:
    """Chi-square cost matrix (n1, n2) between normalised histograms h1 (n1, k) and h2 (n2, k).

    With both histograms summing to 1, 0.5 sum (a - b)^2 / (a + b) = 1 - 2 sum ab / (a + b).
    """
    a, b = h1[:, None, :], h2[None, :, :]
    s = a + b
    return 1.0 - 2.0 * (a * b / (s + (s == 0))).sum(axis=2)


def assignment_cost(h1: np.ndarray, h2: np.ndarray) -> float:
    """Total cost sum_ij C[i, j] X[i, j] of the optimal assignment between two branches' histograms."""
    c = chi_square(h1, h2)
    r, k = linear_sum_assignment(c)
    return float(c[r, k].sum())


def similarity_costs(a: np.ndarray, b: np.ndarray, bins: tuple[int, int, int] = (5, 6, 4)) -> np.ndarray:
    """Optimal-assignment costs (A, B) between resampled branches a (A, n, 3) and b (B, n, 3)."""
    ha, hb = shape_contexts(a, bins), shape_contexts(b, bins)
    return np.array([[assignment_cost(x, y) for y in hb] for x in ha]).reshape(len(ha), len(hb))


def resample_all(polylines: list[np.ndarray], n: int) -> np.ndarray:
    """(B, n, 3) array of each polyline in ``polylines`` resampled to ``n`` vertices."""
    return np.stack([resample_polyline(p, n) for p in polylines]) if polylines else np.zeros((0, n, 3))
