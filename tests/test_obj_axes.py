"""OBJ is Y up: what ``export.obj.write_obj`` writes, ``modules --crown`` (``meshio.load_mesh``) and
``arboretum render`` (``render_cli.read_obj``) read back in the world frame (Z up); files that say
Z up in their header (``save_obj``'s module files, ``write_obj(y_up=False)``) stay Z up."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from arboretum_client.render_cli import read_obj
from arboretum_library.assets import assets_dir
from arboretum_library.cli import main
from arboretum_library.export.gltf import write_glb
from arboretum_library.export.obj import obj_up_axis, write_obj
from arboretum_library.export.parts import Material, MeshPart
from arboretum_server.modules.meshio import load_mesh, save_obj


def _column() -> MeshPart:
    """A 2 x 2 x 6 m box standing on z = 2 (world frame, Z up)."""
    box = trimesh.creation.box(extents=[2, 2, 6])
    return MeshPart("crown", box.vertices + [0.5, -1.0, 5.0], box.faces)


def _bounds(v: np.ndarray) -> np.ndarray:
    return np.stack([v.min(axis=0), v.max(axis=0)])


WORLD = np.array([[-0.5, -2.0, 2.0], [1.5, 0.0, 8.0]])


@pytest.mark.parametrize("y_up", [True, False])
def test_written_obj_reads_back_in_the_world_frame(tmp_path, y_up):
    path = tmp_path / "crown.obj"
    write_obj(path, [_column()], [Material("m")], y_up=y_up)
    assert obj_up_axis(path) == ("y" if y_up else "z")
    v, f = load_mesh(path, "--crown")
    np.testing.assert_allclose(_bounds(v), WORLD, atol=1e-6)
    assert len(f) == 12
    v2, f2 = read_obj(path)
    np.testing.assert_allclose(_bounds(v2), WORLD, atol=1e-6)
    assert len(f2) == 12


def test_obj_and_glb_of_one_mesh_load_alike(tmp_path):
    write_obj(tmp_path / "c.obj", [_column()], [Material("m")])
    write_glb(tmp_path / "c.glb", [_column()], [Material("m")])
    v_obj, _ = load_mesh(tmp_path / "c.obj")
    v_glb, _ = load_mesh(tmp_path / "c.glb")
    np.testing.assert_allclose(np.unique(v_obj.round(5), axis=0), np.unique(v_glb.round(5), axis=0), atol=1e-5)


def test_foreign_obj_without_header_is_y_up(tmp_path):
    """Blender/Maya write OBJ Y up with no axis note: a quad at height y = 5 is at world z = 5."""
    path = tmp_path / "blender.obj"
    path.write_text("# Blender v4.1 OBJ File\no Plane\nv -1 5 1\nv 1 5 1\nv 1 5 -1\nv -1 5 -1\nf 1 2 3 4\n")
    assert obj_up_axis(path) == "y"
    v, _ = read_obj(path)
    np.testing.assert_allclose(v[:, 2], 5.0)
    np.testing.assert_allclose(v[0], [-1, -1, 5])
    v2, _ = load_mesh(path)
    np.testing.assert_allclose(np.sort(v2[:, 2]), 5.0)


def test_save_obj_says_z_up_and_round_trips(tmp_path):
    box = trimesh.creation.box(extents=[1, 1, 4])
    save_obj(tmp_path / "m.obj", box.vertices + [0, 0, 2], box.faces, comment="Arboretum module m")
    assert (tmp_path / "m.obj").read_text().splitlines()[0] == "# arboretum OBJ (Z up, metres)"
    v, _ = load_mesh(tmp_path / "m.obj")
    np.testing.assert_allclose(_bounds(v), [[-0.5, -0.5, 0.0], [0.5, 0.5, 4.0]], atol=1e-5)


def test_legacy_module_files_and_the_bundled_set_stay_z_up(tmp_path):
    legacy = tmp_path / "old.obj"  # what save_obj wrote before it named the axis
    legacy.write_text("# Arboretum module old\n# seed 7\nv 0 0 0\nv 1 0 0\nv 0 0 3\nf 1 2 3\n")
    assert obj_up_axis(legacy) == "z"
    np.testing.assert_allclose(read_obj(legacy)[0][2], [0, 0, 3])
    files = sorted((assets_dir() / "modules" / "default").glob("*.obj"))
    assert len(files) == 25
    for path in files:
        v, _ = load_mesh(path)
        lo, hi = _bounds(v)
        assert abs(lo[2]) < 0.01 and np.argmax(hi - lo) == 2, path.name  # base at z = 0, +Z longest
    trunk, _ = load_mesh(files[-2])
    assert files[-2].name == "trunk_00_straight.obj" and _bounds(trunk)[1, 2] == pytest.approx(3.41, abs=0.01)


def test_modules_help_names_the_axes(capsys):
    with pytest.raises(SystemExit):
        main(["modules", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert ".obj (Y up unless its header says Z up)" in text and ".glb/.gltf (Y up)" in text


@pytest.mark.parametrize("text, axis", [
    ("# Exported by FooScan; axes converted from Z-up to Y-up\nv 0 5 0\nv 1 5 0\nv 0 5 1\nf 1 2 3\n", "y"),
    ("# my crown, Z up\nv 0 5 0\nv 1 5 0\nv 0 5 1\nf 1 2 3\n", "y"),
    ("# Blender\n# z-up\nv 0 5 0\nv 1 5 0\nv 0 5 1\nf 1 2 3\n", "y"),
    ("# arboretum OBJ (Z up, metres)\nv 0 5 0\nv 1 5 0\nv 0 5 1\nf 1 2 3\n", "z"),
    ("# arboretum OBJ (Y up, metres)\n# Z up data, converted\nv 0 5 0\nv 1 5 0\nv 0 5 1\nf 1 2 3\n", "y"),
    ("# Arboretum module branch_00\nv 0 5 0\nv 1 5 0\nv 0 5 1\nf 1 2 3\n", "z"),
])
def test_only_arboretums_own_header_says_z_up(tmp_path, text, axis):
    """A foreign file's comment is no axis claim (before: "converted from Z-up to Y-up" in a Y-up file
    read as Z up, and the crown lay on its side)."""
    path = tmp_path / "c.obj"
    path.write_text(text)
    assert obj_up_axis(path) == axis
    v, _ = read_obj(path)
    np.testing.assert_allclose(v[:, 2 if axis == "y" else 1], 5.0)  # Y up: y = 5 becomes the height
