"""Read module meshes (OBJ, GLB/glTF) into Z-up float64 arrays; write OBJ atomically."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from arboretum_library.checks import check_input_file
from arboretum_library.errors import InputError
from arboretum_library.export.mesh_up import mesh_up_axis
from arboretum_library.export.obj import obj_header
from arboretum_library.geometry import yup_to_zup


def load_mesh(path: str | Path, what: str = "module mesh", up: str = "auto",
              headerless: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 Z up and faces (F, 3) int32 of the mesh in ``path`` (.obj, .glb, .gltf,
    .ply); errors name it as ``what`` (e.g. ``--crown``).

    ``up`` ('auto', 'y', 'z'; ``arboretum_library.export.mesh_up.mesh_up_axis``): glTF is Y up; OBJ is
    read by its Arboretum header (``save_obj``'s module files say Z up), else Y up as Blender and Maya
    write it, and PLY Z up, unless the vertices surely stand along the other axis (``headerless``:
    module pieces, read by header or that axis, never by shape). Coincident vertices are merged.
    """
    import trimesh

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".obj", ".glb", ".gltf", ".ply"):
        raise InputError(
            f"{what} {path}: unsupported format {suffix!r} (use .obj, .ply, .glb or .gltf)"
        )
    check_input_file(str(path), what)
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types on malformed files
        raise InputError(f"{what} {path}: cannot be read ({exc})") from exc
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int32).reshape(-1, 3)
    if len(faces) == 0:
        raise InputError(f"{what} {path}: has no triangles (a point cloud? give a closed mesh)")
    if mesh_up_axis(path, vertices, up, what, headerless) == "y":
        vertices = yup_to_zup(vertices)
    return vertices, faces


def save_obj(path: str | Path, vertices: np.ndarray, faces: np.ndarray, comment: str = "") -> None:
    """Write a triangle mesh (V, 3) / (F, 3) as OBJ (Z up, metres, said on its first line so
    ``load_mesh`` reads it back unchanged) via a temporary file."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    lines = [obj_header(y_up=False)] + [f"# {line}" for line in comment.splitlines()]
    lines += [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in np.asarray(vertices, dtype=np.float64)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces, dtype=np.int64)]
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, path)
