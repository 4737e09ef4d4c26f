"""Write a modular tree (grown in a crown, or converted from a grown tree) as instanced files.

Formats by suffix: ``.glb`` (``EXT_mesh_gpu_instancing``, or plain nodes sharing meshes with
``plain=True``), ``.usdc`` / ``.usda`` / ``.usd`` (``UsdGeom.PointInstancer``). ``flat_size`` writes the
same placed geometry baked into one mesh, in the same format, for the size comparison.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arboretum_library.atomic import write_atomic
from arboretum_library.errors import InputError
from arboretum_library.export.gltf import glb_bytes
from arboretum_library.export.instanced import instanced_glb_bytes, plain_nodes_glb_bytes
from arboretum_library.export.parts import Material, MeshPart

from .moduleset import ModuleSet
from .tree import ModularTree

FORMATS = (".glb", ".usdc", ".usda", ".usd")
BARK = Material("bark", (0.35, 0.25, 0.17, 1.0))


@dataclass(frozen=True, eq=False)
class Instances:
    """Module meshes and where each instance goes: what every instanced writer takes."""

    meshes: tuple[MeshPart, ...]
    """One mesh per module type used, module frame (Z up, metres)."""
    module: np.ndarray
    """(K,) int64 index into ``meshes`` of each instance."""
    T_world_module: np.ndarray
    """(K, 4, 4) float64 world (Z up) from module frame."""
    parent: np.ndarray
    """(K,) int64 parent instance, -1 for roots."""

    @property
    def triangles(self) -> int:
        """Triangles of the whole placed tree (sum over instances)."""
        counts = np.array([len(m.faces) for m in self.meshes])
        return int(counts[self.module].sum())


def from_modular_tree(tree: ModularTree, modules: ModuleSet) -> Instances:
    """The instances of a crown-grown tree; only the module types it uses are kept (in set order)."""
    used, module = np.unique(np.asarray(tree.module, np.int64), return_inverse=True)
    meshes = tuple(MeshPart(modules.modules[i].name, modules.modules[i].vertices, modules.modules[i].faces,
                            vertex_normals(modules.modules[i].vertices, modules.modules[i].faces))
                   for i in used)
    return Instances(meshes, module.astype(np.int64), np.asarray(tree.T_world_module, np.float64),
                     np.asarray(tree.parent, np.int64))


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals of a triangle mesh (V, 3) / (F, 3) (+Z where undefined)."""
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-300, n / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])


def from_converted(conv) -> Instances:
    """The instances of a ``convert.ConvertedTree``."""
    return Instances(tuple(conv.meshes), np.asarray(conv.module, np.int64),
                     np.asarray(conv.T_world_module, np.float64), np.asarray(conv.parent, np.int64))


def flat_part(inst: Instances) -> MeshPart:
    """All instances baked into one world-frame mesh (vertex normals rotated with the instances)."""
    pos, faces, nrm, base = [], [], [], 0
    has_normals = all(m.normals is not None for m in inst.meshes)
    for m, T in zip(inst.module, inst.T_world_module):
        part = inst.meshes[int(m)]
        pos.append(part.positions @ T[:3, :3].T + T[:3, 3])
        if has_normals:
            nrm.append(part.normals @ T[:3, :3].T)
        faces.append(part.faces + base)
        base += len(part.positions)
    if not pos:
        return MeshPart("tree", np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    normals = np.concatenate(nrm) if has_normals else None
    if normals is not None:
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return MeshPart("tree", np.concatenate(pos), np.concatenate(faces), normals)


def check_format(path: str | os.PathLike, plain: bool = False) -> str:
    """The lower-case suffix of ``path`` if it is a supported format (InputError otherwise)."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"--out {path}: unknown format {suffix!r}; use .glb, .usdc, .usda or .usd")
    if plain and suffix != ".glb":
        raise InputError(f"--out {path}: --plain-nodes applies to .glb only")
    if not Path(path).resolve().parent.is_dir():
        raise InputError(f"--out {path}: folder {Path(path).parent} does not exist")
    return suffix


def write_instances(path: str | os.PathLike, inst: Instances, plain: bool = False) -> int:
    """Write ``inst`` to ``path`` (format by suffix) atomically; returns the file size in bytes."""
    suffix = check_format(path, plain)
    if suffix == ".glb":
        make = plain_nodes_glb_bytes if plain else instanced_glb_bytes
        data = make(inst.meshes, [BARK], inst.module, inst.T_world_module)
        write_atomic(path, data)
        return len(data)
    from arboretum_library.export.usd import write_usd_instanced

    return write_usd_instanced(path, inst.meshes, inst.module, inst.T_world_module)


def flat_size(inst: Instances, suffix: str) -> int:
    """Size in bytes of the same tree written as one flat mesh in format ``suffix`` ('.glb', '.usdc', ...)."""
    part = flat_part(inst)
    if suffix == ".glb":
        return len(glb_bytes([part], [BARK]))
    from arboretum_library.export.usd import write_usd_mesh

    with tempfile.TemporaryDirectory(prefix="arboretum-flat-") as tmp:
        return write_usd_mesh(Path(tmp) / f"flat{suffix}", part)
