"""Mesh PLY: texture coordinates read back by trimesh equal the GLB's and OBJ's, and positions far from
the origin (UTM, 1e7 m) survive to 1 mm (double x y z), like the OBJ's 6 decimals."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from plyfile import PlyData

from arboretum_client.render_cli import read_obj, read_ply
from arboretum_library.export.gltf import write_glb
from arboretum_library.export.obj import write_obj
from arboretum_library.export.parts import Material, MeshPart
from arboretum_library.export.ply import mesh_ply_bytes, write_mesh_ply, write_skeleton_ply

MM = 1e-3
FAR = np.array([512345.678, 9876543.21, 312.5])


def _card() -> MeshPart:
    """A leaf card with its texture's top (glTF v = 0) at the card's top."""
    pos = np.array([[0, 0, 1.0], [0.2, 0, 1.0], [0.2, 0, 1.4], [0, 0, 1.4]])
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0.0]])  # glTF: v = 0 is the image's top row
    return MeshPart("leaves", pos, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0, -1.0, 0], (4, 1)), uv, 0)


def _uv(scene_or_mesh) -> np.ndarray:
    m = scene_or_mesh
    if isinstance(m, trimesh.Scene):
        m = next(iter(m.geometry.values()))
    return np.asarray(m.visual.uv, np.float64)


def test_ply_uv_equal_glb_and_obj_uv(tmp_path):
    mats = [Material("leaf", texture_png=None)]
    write_glb(tmp_path / "t.glb", [_card()], mats)
    write_obj(tmp_path / "t.obj", [_card()], mats)
    write_mesh_ply(tmp_path / "t.ply", [_card()])
    glb = _uv(trimesh.load(tmp_path / "t.glb", process=False))
    obj = _uv(trimesh.load(tmp_path / "t.obj", process=False))
    ply = _uv(trimesh.load(tmp_path / "t.ply", process=False))
    expected = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])  # bottom-left origin: top of the card v = 1
    np.testing.assert_allclose(glb, expected, atol=1e-6)
    np.testing.assert_allclose(obj, expected, atol=1e-6)
    np.testing.assert_allclose(ply, expected, atol=1e-6)


def _far_mesh() -> MeshPart:
    s = trimesh.creation.icosphere(4, radius=0.3)  # edges ~ 1.5 cm
    return MeshPart("bark", s.vertices + FAR, s.faces, s.vertex_normals, np.zeros((len(s.vertices), 2)), 0)


def _areas(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


def _check_far(v: np.ndarray, f: np.ndarray, part: MeshPart) -> None:
    assert np.abs(v - part.positions).max() < MM
    assert _areas(v, f).min() > 0.5 * _areas(part.positions, part.faces).min()  # no collapsed triangle


def test_far_ply_is_exact_to_a_millimetre(tmp_path):
    part = _far_mesh()
    write_mesh_ply(tmp_path / "far.ply", [part])
    ply = PlyData.read(str(tmp_path / "far.ply"))
    assert ply["vertex"].data.dtype["x"] == np.dtype("<f8") and ply["vertex"].data.dtype["nx"] == np.dtype("<f4")
    v = np.stack([ply["vertex"][k] for k in "xyz"], axis=1)
    _check_far(v, part.faces, part)
    tm = trimesh.load(tmp_path / "far.ply", process=False)
    _check_far(np.asarray(tm.vertices), np.asarray(tm.faces), part)
    v2, f2 = read_ply(tmp_path / "far.ply")
    _check_far(v2, f2, part)


def test_near_ply_keeps_float32(rng):
    part = MeshPart("bark", rng.normal(size=(10, 3)) * 100, np.array([[0, 1, 2]]))
    head = mesh_ply_bytes([part]).split(b"end_header")[0].decode()
    assert "property float x" in head and "double" not in head


def test_far_obj_is_exact_to_a_millimetre(tmp_path):
    part = _far_mesh()
    write_obj(tmp_path / "far.obj", [part], [Material("bark")])
    v, f = read_obj(tmp_path / "far.obj")
    _check_far(v, f, part)
    from arboretum_server.modules.meshio import load_mesh

    v2, f2 = load_mesh(tmp_path / "far.obj")
    assert len(v2) == len(part.positions)
    tree = trimesh.load(tmp_path / "far.obj", force="mesh", process=False)
    zup = np.c_[tree.vertices[:, 0], -tree.vertices[:, 2], tree.vertices[:, 1]]
    _check_far(zup, np.asarray(tree.faces), part)


@pytest.mark.parametrize("offset, dtype", [(np.zeros(3), "<f4"), (FAR, "<f8")])
def test_skeleton_ply_far(tmp_path, offset, dtype):
    pos = np.array([[0, 0, 0], [0, 0, 1.0], [0.001, 0, 1.5]]) + offset
    write_skeleton_ply(tmp_path / "s.ply", pos, np.array([0.1, 0.05, 0.01]), np.array([-1, 0, 1]))
    ply = PlyData.read(str(tmp_path / "s.ply"))
    assert ply["vertex"].data.dtype["x"] == np.dtype(dtype)
    v = np.stack([ply["vertex"][k] for k in "xyz"], axis=1)
    assert np.abs(v - pos).max() < MM
