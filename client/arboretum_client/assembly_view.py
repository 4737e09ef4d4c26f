"""Placed examples in the world frame: plain numpy over library records (no GL).

A placement's example is drawn as ``T_world_example @ (scale * p_example)``; a lobe transform
``T_example_lobe`` acts about the lobe centre in the example frame first:
``p' = c + A (p - c) + t`` with ``A = T[:3, :3]`` (rotation times uniform scale), ``t = T[:3, 3]``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from arboretum_library.assembly import Placement
from arboretum_library.model import HBL, Lobe


def about_centre(T: np.ndarray, centre: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply similarity ``T`` (4, 4) about ``centre`` (3,) to ``points`` (N, 3)."""
    return centre + (np.asarray(points, float) - centre) @ T[:3, :3].T + T[:3, 3]


def _move_lobe(lobe: Lobe, T: np.ndarray) -> Lobe:
    c = lobe.centre
    return dataclasses.replace(lobe, points=about_centre(T, c, lobe.points),
                               hull_vertices=about_centre(T, c, lobe.hull_vertices), centre=c + T[:3, 3])


def to_world(T_world_example: np.ndarray, scale: float, points: np.ndarray) -> np.ndarray:
    """(N, 3) example-frame points -> world."""
    pts = np.asarray(points, float).reshape(-1, 3) * scale
    return pts @ T_world_example[:3, :3].T + T_world_example[:3, 3]


def placed_hbl(hbl: HBL, p: Placement) -> HBL:
    """``hbl`` (example frame) with the placement's lobe transforms, scale and pose applied (world)."""
    lobes = list(hbl.lobes)
    for lt in p.lobe_transforms:
        lobes[lt.lobe] = _move_lobe(lobes[lt.lobe], lt.T_example_lobe)
    T, s = p.T_world_example, p.scale

    def w(x):
        return to_world(T, s, x)

    branches = tuple(dataclasses.replace(b, points=w(b.points), radii=b.radii * s) for b in hbl.branches)
    lobes_w = tuple(dataclasses.replace(lb, points=w(lb.points), hull_vertices=w(lb.hull_vertices),
                                        centre=w(lb.centre)[0]) for lb in lobes)
    return HBL(w(hbl.root)[0], branches, lobes_w, w(hbl.points), hbl.labels)


def rigid(R: np.ndarray | None = None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) rigid transform from a rotation (3, 3) and translation (3,)."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def rot_z(angle: float) -> np.ndarray:
    """(3, 3) rotation about +Z by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """The nearest rotation to ``R`` (3, 3) (SVD), determinant +1."""
    U, _, Vt = np.linalg.svd(R)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return U @ D @ Vt
