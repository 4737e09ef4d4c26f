"""OBJ + MTL, mesh PLY, skeleton PLY (vertex + edge) and skeleton JSON."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from plyfile import PlyData

from arboretum_library.errors import InputError
from arboretum_library.export.obj import write_obj
from arboretum_library.export.parts import Material, MeshPart
from arboretum_library.export.ply import write_mesh_ply, write_skeleton_ply
from arboretum_library.export.skeleton import read_skeleton_json, write_skeleton_json

PNG = b"\x89PNG\r\n\x1a\n" + b"\x00" * 16


def _parts(rng):
    box = trimesh.creation.box((1, 2, 3))
    quad = MeshPart("card", rng.normal(size=(4, 3)), np.array([[0, 1, 2], [0, 2, 3]]),
                    np.tile([0, 0, 1.0], (4, 1)), np.array([[0, 1], [1, 1], [1, 0], [0, 0.0]]), 1)
    bark = MeshPart("bark", box.vertices + [0, 0, 1.5], box.faces, box.vertex_normals,
                    rng.uniform(size=(8, 2)), 0)
    mats = [Material("bark", texture_png=PNG, texture_name="bark.png"),
            Material("leaf", texture_png=PNG, texture_name="leaf.png", alpha_cutoff=0.5)]
    return [bark, quad], mats


def test_obj_mtl_round_trip(tmp_path, rng):
    parts, mats = _parts(rng)
    files = write_obj(tmp_path / "t.obj", parts, mats)
    assert sorted(f.name for f in files) == ["t.mtl", "t.obj", "t_bark.png", "t_leaf.png"]
    text = (tmp_path / "t.obj").read_text().splitlines()
    assert sum(line.startswith("v ") for line in text) == 12
    assert sum(line.startswith("f ") for line in text) == 14
    mtl = (tmp_path / "t.mtl").read_text()
    assert "map_Kd t_bark.png" in mtl and "map_d t_leaf.png" in mtl
    v = np.array([line.split()[1:] for line in text if line.startswith("v ")], float)
    assert v[:8, 1].max() == pytest.approx(3.0, abs=1e-5)  # Y up: world z (0..3) became y
    m = trimesh.load(tmp_path / "t.obj", force="mesh", process=False)
    assert len(m.faces) == 14
    last = [line for line in text if line.startswith("f ")][-1].split()[1]
    assert last.count("/") == 2 and int(last.split("/")[0]) > 8  # offsets past the first part


def test_mesh_ply(tmp_path, rng):
    parts, _ = _parts(rng)
    write_mesh_ply(tmp_path / "t.ply", parts)
    ply = PlyData.read(str(tmp_path / "t.ply"))
    assert ply["vertex"].count == 12 and ply["face"].count == 14
    faces = np.stack(ply["face"]["vertex_indices"])
    assert faces.max() == 11 and faces[12:].min() == 8
    assert np.allclose(ply["vertex"]["z"][:8], parts[0].positions[:, 2])  # Z up kept


def test_skeleton_ply_and_json(tmp_path, rng):
    pos = rng.normal(size=(6, 3))
    parents = np.array([-1, 0, 1, 1, 3, 0])
    radii = np.array([0.5, 0.4, 0.2, 0.3, 0.2, 0.1])
    levels = np.array([0, 0, 1, 1, 2, 2])
    write_skeleton_ply(tmp_path / "s.ply", pos, radii, parents, levels)
    ply = PlyData.read(str(tmp_path / "s.ply"))
    assert ply["vertex"].count == 6 and ply["edge"].count == 5
    assert np.allclose(ply["vertex"]["radius"], radii)
    assert ply["edge"]["vertex1"].tolist() == [0, 1, 1, 3, 0]
    assert ply["edge"]["vertex2"].tolist() == [1, 2, 3, 4, 5]
    write_skeleton_json(tmp_path / "s.json", pos, radii, parents, levels)
    back = read_skeleton_json(tmp_path / "s.json")
    assert np.allclose(back["positions"], pos, atol=1e-4)
    assert back["parents"].tolist() == parents.tolist() and back["levels"].tolist() == levels.tolist()
    assert np.allclose(back["radii"], radii)
    (tmp_path / "bad.json").write_text('{"format": "other"}')
    with pytest.raises(InputError, match="not an arboretum-skeleton"):
        read_skeleton_json(tmp_path / "bad.json")
