"""Default crown meshes for tests and demos (closed, outward-facing, world frame Z up, metres)."""

from __future__ import annotations

import numpy as np


def sphere_mesh(centre, radius: float, subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Icosphere: vertices (V, 3), faces (F, 3)."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + np.asarray(centre, dtype=np.float64), np.asarray(
        m.faces, dtype=np.int32
    )


def torus_mesh(
    centre, major: float, minor: float, axis: str = "z", n_major: int = 48, n_minor: int = 16
):
    """Torus around ``axis`` ('x', 'y' or 'z') through ``centre``: vertices (V, 3), faces (F, 3)."""
    u = 2 * np.pi * np.arange(n_major) / n_major
    v = 2 * np.pi * np.arange(n_minor) / n_minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    p = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], axis=-1).reshape(-1, 3)
    perm = {"z": [0, 1, 2], "x": [2, 0, 1], "y": [1, 2, 0]}[axis]
    p = p[:, perm] + np.asarray(centre, dtype=np.float64)
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = i * n_minor + j
    b = ((i + 1) % n_major) * n_minor + j
    c = ((i + 1) % n_major) * n_minor + (j + 1) % n_minor
    d = i * n_minor + (j + 1) % n_minor
    faces = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return p, _outward(p, faces.astype(np.int32))


def tetrahedron_mesh(centre, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Regular tetrahedron with a horizontal bottom face and the apex up; edge about ``size``."""
    h = size * np.sqrt(2 / 3)
    r = size / np.sqrt(3)
    ang = np.radians([90, 210, 330])
    base = np.stack([r * np.cos(ang), r * np.sin(ang), np.full(3, -h / 4)], axis=1)
    v = np.concatenate([base, [[0, 0, 3 * h / 4]]]) + np.asarray(centre, dtype=np.float64)
    faces = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], dtype=np.int32)
    return v, _outward(v, faces)


def box_mesh(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box from ``lo`` (3,) to ``hi`` (3,)."""
    import trimesh

    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    m = trimesh.creation.box(extents=hi - lo)
    return np.asarray(m.vertices) + (lo + hi) / 2, np.asarray(m.faces, dtype=np.int32)


def _outward(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Flip all faces if the signed volume is negative (consistent winding assumed)."""
    t = vertices[faces]
    vol = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum()
    return faces if vol > 0 else faces[:, ::-1].copy()
