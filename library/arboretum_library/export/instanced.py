"""Instanced GLB: one mesh per module type, placed many times.

Two variants of the same content:

- ``instanced_glb_bytes``: one node per used mesh carrying ``EXT_mesh_gpu_instancing`` with TRANSLATION,
  ROTATION (unit quaternion, xyzw) and SCALE accessors (float32, one row per instance). The extension is
  declared in ``extensionsUsed`` and ``extensionsRequired``.
- ``plain_nodes_glb_bytes``: one plain node per instance, all nodes of a type sharing one mesh (for
  importers without the extension, e.g. trimesh).

Transforms are world (Z up) similarities ``T = [s R | t]`` mapping a mesh's own frame to the world. glTF is
Y up, so with ``C`` the Z-up -> Y-up rotation the written transform is ``C T C^T``: translation ``C t``,
rotation ``C R C^T`` (the frame is rotated, not only the positions), scale unchanged. The float32
TRANSLATION accessors hold translations relative to ``parts.local_origin`` of the instances (zero near
the world origin); the instancing nodes then hang under a root node "origin" translated (float64 JSON)
by ``C`` times it. numpy + stdlib only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from arboretum_library.errors import ValidationError

from .gltf import C_YUP_ZUP, _Builder, _materials, _primitive, glb_bytes, pack_glb, root_at
from .parts import Material, MeshPart, Node, local_origin

EXTENSION = "EXT_mesh_gpu_instancing"


def decompose_similarity(T: np.ndarray, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Translation (K, 3), rotation (K, 3, 3) and uniform scale (K,) of similarities ``T`` (K, 4, 4).

    Raises ValidationError when a transform is not a proper rotation times a positive uniform scale.
    """
    T = np.asarray(T, np.float64).reshape(-1, 4, 4)
    M = T[:, :3, :3]
    scale = np.cbrt(np.linalg.det(M)) if len(T) else np.zeros(0)
    if np.any(scale <= 0):
        raise ValidationError("instance transforms: scale must be positive (no mirroring)")
    R = M / scale[:, None, None]
    err = np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2)) if len(T) else np.zeros(0)
    if np.any(err > tol):
        raise ValidationError(f"instance transforms: instance {int(np.argmax(err))} is not a uniform "
                              "scale times a rotation")
    return T[:, :3, 3].copy(), R, scale


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (K, 4) as (x, y, z, w), w >= 0, of rotations ``R`` (K, 3, 3) (Shepperd's method)."""
    R = np.asarray(R, np.float64).reshape(-1, 3, 3)
    tr = np.trace(R, axis1=1, axis2=2)
    diag = np.stack([R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    pick = np.argmax(np.concatenate([tr[:, None], diag], axis=1), axis=1)
    q = np.zeros((len(R), 4))
    for case in range(4):
        m = pick == case
        r = R[m]
        if case == 0:
            s = 2 * np.sqrt(1 + tr[m])
            q[m] = np.stack([(r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                             (r[:, 1, 0] - r[:, 0, 1]) / s, s / 4], axis=1)
            continue
        i = case - 1
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2 * np.sqrt(np.maximum(1 + r[:, i, i] - r[:, j, j] - r[:, k, k], 1e-300))
        v = np.zeros((len(r), 4))
        v[:, i] = s / 4
        v[:, j] = (r[:, j, i] + r[:, i, j]) / s
        v[:, k] = (r[:, k, i] + r[:, i, k]) / s
        v[:, 3] = (r[:, k, j] - r[:, j, k]) / s
        q[m] = v
    q *= np.where(q[:, 3:] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def instance_trs_yup(T_world: np.ndarray, origin: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """glTF (Y up) translation (K, 3), rotation xyzw (K, 4) and scale (K, 3), all float32, of ``T_world``;
    translations relative to ``origin`` (3,) (world, Z up) when given."""
    t, R, s = decompose_similarity(T_world)
    if origin is not None:
        t = t - origin
    C = C_YUP_ZUP
    t_y = t @ C.T
    R_y = C @ R @ C.T
    q = matrix_to_quat_xyzw(R_y)
    return (t_y.astype(np.float32), q.astype(np.float32),
            np.repeat(s[:, None], 3, axis=1).astype(np.float32))


def _check(meshes: Sequence[MeshPart], mesh_index: np.ndarray, T_world: np.ndarray) -> None:
    if len(mesh_index) != len(T_world):
        raise ValidationError(f"instances: {len(mesh_index)} mesh indices but {len(T_world)} transforms")
    if len(mesh_index) and (mesh_index.min() < 0 or mesh_index.max() >= len(meshes)):
        raise ValidationError(f"instances: mesh indices must lie in 0..{len(meshes) - 1}")


def instanced_glb_bytes(meshes: Sequence[MeshPart], materials: Sequence[Material],
                        mesh_index: np.ndarray, T_world: np.ndarray) -> bytes:
    """GLB with one ``EXT_mesh_gpu_instancing`` node per used mesh.

    Args:
        meshes: module meshes in their own frame (Z up, metres).
        materials: the materials the meshes refer to.
        mesh_index: (K,) int, the mesh of each instance.
        T_world: (K, 4, 4) float64 world (Z up) similarities from mesh frame to world.

    Instances of mesh m appear in the node's accessors in the order they have in ``mesh_index``.
    """
    mesh_index = np.asarray(mesh_index, np.int64).reshape(-1)
    T_world = np.asarray(T_world, np.float64).reshape(-1, 4, 4)
    _check(meshes, mesh_index, T_world)
    origin = local_origin(T_world[:, :3, 3])
    t, q, s = instance_trs_yup(T_world, origin)
    b = _Builder()
    _materials(b, materials)
    for m in np.unique(mesh_index):
        part = meshes[int(m)]
        if len(part.faces) == 0:
            continue
        b.doc["meshes"].append({"name": part.name, "primitives": [_primitive(b, part)]})
        sel = np.flatnonzero(mesh_index == m)
        attrs = {"TRANSLATION": b.accessor(t[sel], "VEC3", None),
                 "ROTATION": b.accessor(q[sel], "VEC4", None),
                 "SCALE": b.accessor(s[sel], "VEC3", None)}
        b.doc["nodes"].append({"mesh": len(b.doc["meshes"]) - 1, "name": f"{part.name}_instances",
                               "extensions": {EXTENSION: {"attributes": attrs}}})
        b.doc["scenes"][0]["nodes"].append(len(b.doc["nodes"]) - 1)
    root_at(b, origin)
    if b.doc["nodes"]:
        b.doc["extensionsUsed"] = [EXTENSION]
        b.doc["extensionsRequired"] = [EXTENSION]
    return pack_glb(b)


def plain_nodes_glb_bytes(meshes: Sequence[MeshPart], materials: Sequence[Material],
                          mesh_index: np.ndarray, T_world: np.ndarray) -> bytes:
    """GLB with one plain node per instance (same arguments as ``instanced_glb_bytes``)."""
    mesh_index = np.asarray(mesh_index, np.int64).reshape(-1)
    T_world = np.asarray(T_world, np.float64).reshape(-1, 4, 4)
    _check(meshes, mesh_index, T_world)
    decompose_similarity(T_world)
    nodes = [Node(int(m), T, f"{meshes[int(m)].name}_{i}") for i, (m, T) in enumerate(zip(mesh_index, T_world))]
    return glb_bytes(meshes, materials, nodes)
