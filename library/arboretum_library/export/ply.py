"""Binary little-endian PLY writers: a triangle mesh, and a skeleton (vertices with radii + edges).

PLY keeps the world frame (Z up, metres), like the scans it sits beside. numpy only. Positions are
float32, or double when a coordinate exceeds ``FLOAT32_LIMIT`` (float32 resolves only 0.5 m at UTM
northings of 5.4e6 m; trimesh, Open3D, plyfile, Blender and MeshLab read double properties). Texture
coordinates (s, t) have their origin at the image's bottom-left, as PLY readers and OBJ expect, so t is
flipped from the glTF convention of ``MeshPart.uv``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from arboretum_library.atomic import write_atomic

from .parts import MeshPart

FLOAT32_LIMIT = 1024.0
"""Largest |coordinate| (m) written as float32 (resolution 61 µm or better); beyond it, double."""


def _position_type(positions: np.ndarray) -> tuple[str, str]:
    """(numpy dtype, PLY type name) for ``positions`` (N, 3): float32 near the origin, else double."""
    p = np.asarray(positions)
    if len(p) and np.abs(p).max() > FLOAT32_LIMIT:
        return "<f8", "double"
    return "<f4", "float"


def _header(elements: list[tuple[str, int, list[str]]]) -> bytes:
    lines = ["ply", "format binary_little_endian 1.0", "comment arboretum, Z up, metres"]
    for name, count, props in elements:
        lines.append(f"element {name} {count}")
        lines.extend(props)
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


def _merged(meshes: Sequence[MeshPart]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions, normals (zeros when absent), uv (zeros when absent) and faces of all meshes as one."""
    pos, nrm, uv, faces, offset = [np.zeros((0, 3))], [np.zeros((0, 3))], [np.zeros((0, 2))], [], 0
    for m in meshes:
        n = len(m.positions)
        pos.append(m.positions)
        nrm.append(m.normals if m.normals is not None else np.zeros((n, 3)))
        uv.append(m.uv if m.uv is not None else np.zeros((n, 2)))
        faces.append(m.faces + offset)
        offset += n
    f = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(uv), f


def mesh_ply_bytes(meshes: Sequence[MeshPart]) -> bytes:
    """All ``meshes`` merged into one PLY: x y z (float32, or double far from the origin), float nx ny
    nz, float s t (t = 1 - v: bottom-left origin), and uchar-count int faces."""
    pos, nrm, uv, faces = _merged(meshes)
    ptype, pname = _position_type(pos)
    names = ("x", "y", "z", "nx", "ny", "nz", "s", "t")
    vdt = np.dtype([(k, ptype if k in "xyz" else "<f4") for k in names])
    v = np.zeros(len(pos), vdt)
    for i, k in enumerate(("x", "y", "z")):
        v[k], v["n" + k] = pos[:, i], nrm[:, i]
    v["s"], v["t"] = uv[:, 0], 1.0 - uv[:, 1]
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    f = np.zeros(len(faces), fdt)
    f["n"], f["i"] = 3, faces
    head = _header([
        ("vertex", len(v), [f"property {pname if k in 'xyz' else 'float'} {k}" for k in names]),
        ("face", len(f), ["property list uchar int vertex_indices"]),
    ])
    return head + v.tobytes() + f.tobytes()


def skeleton_ply_bytes(positions: np.ndarray, radii: np.ndarray, parents: np.ndarray,
                       levels: np.ndarray | None = None) -> bytes:
    """Skeleton PLY: vertex (x y z radius [level]) and edge (vertex1 vertex2 = parent, child); x y z
    float32, or double far from the origin."""
    n = len(positions)
    ptype, _ = _position_type(positions)
    names = [("x", ptype), ("y", ptype), ("z", ptype), ("radius", "<f4")]
    if levels is not None:
        names.append(("level", "u1"))
    v = np.zeros(n, np.dtype(names))
    v["x"], v["y"], v["z"] = positions[:, 0], positions[:, 1], positions[:, 2]
    v["radius"] = radii
    if levels is not None:
        v["level"] = levels
    child = np.flatnonzero(np.asarray(parents) >= 0)
    e = np.zeros(len(child), np.dtype([("vertex1", "<i4"), ("vertex2", "<i4")]))
    e["vertex1"], e["vertex2"] = np.asarray(parents)[child], child
    kinds = {"<f4": "float", "<f8": "double", "u1": "uchar"}
    props = [f"property {kinds[t]} {k}" for k, t in names]
    edge_props = ["property int vertex1", "property int vertex2"]
    head = _header([("vertex", n, props), ("edge", len(e), edge_props)])
    return head + v.tobytes() + e.tobytes()


def write_mesh_ply(path: str | os.PathLike, meshes: Sequence[MeshPart]) -> int:
    data = mesh_ply_bytes(meshes)
    write_atomic(path, data)
    return len(data)


def write_skeleton_ply(path: str | os.PathLike, positions: np.ndarray, radii: np.ndarray,
                       parents: np.ndarray, levels: np.ndarray | None = None) -> int:
    data = skeleton_ply_bytes(positions, radii, parents, levels)
    write_atomic(path, data)
    return len(data)
