"""Write a grown tree's mesh and skeleton in the format named by the file extension."""

from __future__ import annotations

from pathlib import Path

from arboretum_library.export.gltf import write_glb
from arboretum_library.export.obj import check_sidecars, write_obj
from arboretum_library.export.ply import write_mesh_ply, write_skeleton_ply
from arboretum_library.export.skeleton import write_skeleton_json
from arboretum_server.mesh.scene import TreeMesh, tree_materials

from .skeleton import GrownTree


def check_obj_sidecars(out: Path) -> None:
    """An .obj ``out``: its .mtl and textures refused now, not after growth, when Arboretum did not write
    them (``export.obj.check_sidecars`` with the materials ``write_mesh`` uses)."""
    if out.suffix.lower() == ".obj":
        check_sidecars(out, tree_materials())


def write_mesh(path: Path, mesh: TreeMesh) -> int:
    """GLB (Y up, textures embedded), OBJ + MTL + PNGs (Y up) or PLY (Z up); returns bytes written."""
    suffix = path.suffix.lower()
    if suffix == ".glb":
        return write_glb(path, mesh.parts, tree_materials())
    if suffix == ".obj":
        files = write_obj(path, mesh.parts, tree_materials())
        return sum(f.stat().st_size for f in files)
    return write_mesh_ply(path, mesh.parts)


def write_skeleton(path: Path, tree: GrownTree) -> int:
    """Skeleton with radii as JSON or PLY (vertex + edge elements), world frame (Z up)."""
    if path.suffix.lower() == ".json":
        return write_skeleton_json(path, tree.positions, tree.radii, tree.parents, tree.levels)
    return write_skeleton_ply(path, tree.positions, tree.radii, tree.parents, tree.levels)
