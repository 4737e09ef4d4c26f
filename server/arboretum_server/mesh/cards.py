"""Leaf cards: one double-sided quad per leaf, the leaf texture's stem at the node and its tip outward."""

from __future__ import annotations

import numpy as np

from arboretum_library.export.parts import MeshPart

WIDTH = 0.5
"""Card width as a fraction of its length (matches the leaf texture's aspect)."""


def card_mesh(centres: np.ndarray, normals: np.ndarray, axes: np.ndarray, sizes: np.ndarray,
              name: str = "leaves", material: int = 1) -> MeshPart:
    """Quads (4K vertices, 2K triangles) for K cards; CCW seen from the side ``normals`` point to.

    Corner order: stem-left, stem-right, tip-right, tip-left, where 'right' is ``axes × normals``.
    UVs put the stem at the image's bottom (v = 1) and the tip at its top (v = 0).
    """
    k = len(centres)
    half_l = (axes * sizes[:, None] / 2)[:, None]
    side = np.cross(axes, normals)
    half_w = (side * sizes[:, None] * WIDTH / 2)[:, None]
    sign_l = np.array([-1, -1, 1, 1], float)[None, :, None]
    sign_w = np.array([-1, 1, 1, -1], float)[None, :, None]
    pos = centres[:, None] + sign_l * half_l + sign_w * half_w
    uv = np.tile(np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]), (k, 1))
    base = 4 * np.arange(k)[:, None]
    faces = (base[:, None] + np.array([[0, 1, 2], [0, 2, 3]])[None]).reshape(-1, 3)
    nrm = np.repeat(normals, 4, axis=0)
    return MeshPart(name, pos.reshape(-1, 3), faces, nrm, uv, material)
