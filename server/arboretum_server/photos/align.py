"""Comparing a reconstruction with a known shape: Umeyama similarity alignment and Chamfer distances.

Used to check photogrammetry against synthetic trees (tests, bench): the reconstructed camera centres
are aligned to the true ones (Umeyama 1991, least squares over scale, rotation and translation), the
same similarity maps the cloud, and the Chamfer distances to the true surface tell how close it lies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Similarity:
    """``p_dst = scale * R @ p_src + t``."""

    scale: float
    R: np.ndarray
    """(3, 3) float64 rotation."""
    t: np.ndarray
    """(3,) float64 translation."""

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``points`` (N, 3) mapped into the destination frame."""
        return self.scale * np.asarray(points, np.float64) @ self.R.T + self.t


def umeyama(src: np.ndarray, dst: np.ndarray) -> Similarity:
    """The similarity minimising sum |dst_i - (s R src_i + t)|^2 over corresponding (N, 3) points, N >= 3."""
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        raise ValueError(f"need two (N, 3) arrays with N >= 3, got {src.shape} and {dst.shape}")
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(cov)
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1.0
    R = U @ D @ Vt
    var = (a * a).sum() / len(src)
    s = float(np.trace(np.diag(S) @ D) / var) if var > 0 else 1.0
    return Similarity(s, R, mu_d - s * R @ mu_s)


def chamfer(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Mean nearest-neighbour distance from ``a`` (N, 3) to ``b`` (M, 3), and from ``b`` to ``a``."""
    from scipy.spatial import cKDTree

    ab = cKDTree(b).query(a)[0]
    ba = cKDTree(a).query(b)[0]
    return float(ab.mean()), float(ba.mean())
