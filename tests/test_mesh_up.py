"""``--up`` for mesh inputs (``render``, ``modules --crown``): Arboretum's header, else the format's
usual axis unless the vertices surely stand along the other (a tree exported Z up without our header
used to lie on its side)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from arboretum_client.render_cli import read_input, read_obj
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.export.mesh_up import mesh_up_axis
from arboretum_library.geometry import zup_to_yup
from arboretum_server.modules.meshio import load_mesh


def _tree_zup() -> trimesh.Trimesh:
    """A 6 m tree, Z up: a trunk 0.3 m across up to 4 m, a crown 3 m across centred at 4.5 m."""
    trunk = trimesh.creation.cylinder(radius=0.15, height=4.0)
    trunk.apply_translation([0, 0, 2.0])
    crown = trimesh.creation.icosphere(subdivisions=3, radius=1.5)
    crown.apply_translation([0, 0, 4.5])
    return trimesh.util.concatenate([trunk, crown])


def _write_obj(path, verts, faces, header="# exported by SomeTool 2.1"):
    lines = [header] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _height_axis(verts) -> int:
    return int(np.argmax(np.ptp(verts, axis=0)))


@pytest.fixture
def files(tmp_path):
    tree = _tree_zup()
    v, f = np.asarray(tree.vertices), np.asarray(tree.faces)
    out = {
        "obj_z": _write_obj(tmp_path / "zup.obj", v, f),
        "obj_y": _write_obj(tmp_path / "yup.obj", zup_to_yup(v), f, "# Blender 4.1"),
        "ply_z": tmp_path / "zup.ply",
        "ply_y": tmp_path / "yup.ply",
    }
    trimesh.Trimesh(v, f, process=False).export(out["ply_z"])
    trimesh.Trimesh(zup_to_yup(v), f, process=False).export(out["ply_y"])
    return out


@pytest.mark.parametrize("name", ["obj_z", "obj_y", "ply_z", "ply_y"])
def test_a_tree_is_read_upright_whichever_axis_its_file_has(files, name):
    path = files[name]
    assert mesh_up_axis(path, _raw(path)) == name[-1]
    v, _ = load_mesh(path, "--crown")
    assert _height_axis(v) == 2 and v[:, 2].min() == pytest.approx(0.0, abs=1e-5)  # standing on z = 0
    assert v[:, 2].max() == pytest.approx(6.0, abs=1e-3)
    corners, _ = read_input(path, None)
    assert corners[1, 2] - corners[0, 2] == pytest.approx(6.0, abs=1e-3)


def _raw(path):
    m = trimesh.load(path, force="mesh", process=False)
    return np.asarray(m.vertices)


def test_an_explicit_up_wins_over_the_guess(files):
    v, _ = read_obj(files["obj_z"], "y")  # told Y up: the tree lies along -Y
    assert _height_axis(v) == 1
    v, _ = load_mesh(files["obj_y"], "--crown", "z")
    assert _height_axis(v) == 1


def test_an_unsure_guess_keeps_the_formats_axis(tmp_path):
    # a round crown is no more upright along Z than along Y: an OBJ stays Y up, a PLY Z up
    ball = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    path = _write_obj(tmp_path / "ball.obj", ball.vertices, ball.faces)
    assert mesh_up_axis(path, np.asarray(ball.vertices)) == "y"
    ply = tmp_path / "ball.ply"
    ball.export(ply)
    assert mesh_up_axis(ply, np.asarray(ball.vertices)) == "z"


def test_arboretums_header_decides_even_against_the_shape(files, tmp_path):
    tree = _tree_zup()
    path = _write_obj(tmp_path / "ours.obj", zup_to_yup(tree.vertices), tree.faces,
                      "# arboretum OBJ (Y up, metres)")
    assert mesh_up_axis(path, np.asarray(tree.vertices)) == "y"  # vertices as if Z up: the header wins


def test_gltf_is_y_up_and_up_z_is_refused(tmp_path, capsys):
    glb = tmp_path / "t.glb"
    _tree_zup().export(glb)
    assert mesh_up_axis(glb, np.zeros((0, 3))) == "y" and mesh_up_axis(glb, np.zeros((0, 3)), "y") == "y"
    with pytest.raises(InputError, match=r"t\.glb: glTF is Y up by definition"):
        mesh_up_axis(glb, np.zeros((0, 3)), "z")
    code = main(["render", str(glb), "--out", str(tmp_path / "x.png"), "--up", "z"])
    err = capsys.readouterr().err
    assert code == 2 and "glTF is Y up" in err and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


def test_modules_passes_up_to_its_crown(files, monkeypatch, tmp_path, capsys):
    from arboretum_server.modules import meshio

    seen = []

    real = meshio.load_mesh

    def stop(path, what="module mesh", up="auto", headerless=None):
        if what != "--crown":
            return real(path, what, up, headerless)  # the bundled module meshes
        seen.append(up)
        raise InputError("stop here")

    monkeypatch.setattr(meshio, "load_mesh", stop)
    for up in ("auto", "z"):
        argv = ["modules", "--crown", str(files["obj_z"]), "--out", str(tmp_path / "m.glb")]
        assert main(argv + (["--up", up] if up != "auto" else [])) == 2
    assert seen == ["auto", "z"] and "stop here" in capsys.readouterr().err


def test_arboretums_own_ply_is_z_up_whatever_its_shape(tmp_path):
    # a row of five trees along Y, written by our PLY writer: wider along Y than tall, which the
    # shape test alone would read as a tree lying along Y
    from arboretum_library.export.parts import MeshPart
    from arboretum_library.export.ply import write_mesh_ply

    tree = _tree_zup()
    row = trimesh.util.concatenate([tree.copy().apply_translation([0, 8.0 * i, 0]) for i in range(5)])
    v = np.asarray(row.vertices)
    part = MeshPart(name="row", positions=v, faces=np.asarray(row.faces))
    path = tmp_path / "row.ply"
    write_mesh_ply(path, [part])
    assert mesh_up_axis(path, v) == "z"
    headerless = tmp_path / "row_other.ply"
    trimesh.Trimesh(v, row.faces, process=False).export(headerless)
    assert mesh_up_axis(headerless, v) == "y"  # without our comment the shape decides (documented)


def test_module_meshes_are_never_guessed(tmp_path):
    # a leaf card lying in the XZ plane of a headerless OBJ (Y up): read Y up, not guessed
    card = np.array([[0, 0, 0], [0.05, 0, 0], [0.05, 0, 0.12], [0, 0, 0.12]], float)
    verts = np.vstack([card + [0, 0.001 * i, 0] for i in range(3)])
    faces = np.vstack([[4 * i, 4 * i + 1, 4 * i + 2] for i in range(3)] + [[4 * i, 4 * i + 2, 4 * i + 3] for i in range(3)])
    path = _write_obj(tmp_path / "leaf.obj", verts, faces)
    assert mesh_up_axis(path, verts, headerless="auto") == "y"
    v, _ = load_mesh(path, headerless="auto")
    np.testing.assert_allclose(np.ptp(v, axis=0)[1], 0.12, atol=1e-6)  # the card's length lies along -Y


def _folder_with(tmp_path, **meshes):
    folder = tmp_path / "mods"
    folder.mkdir()
    for name, (mesh, header) in meshes.items():
        _write_obj(folder / f"{name}.obj", np.asarray(mesh.vertices), np.asarray(mesh.faces), header)
    return folder


def test_a_module_folder_is_read_by_header_or_modules_up_never_by_shape(tmp_path):
    from arboretum_server.modules.moduleset import load_module_set

    branch = trimesh.creation.cylinder(radius=0.03, height=1.0, sections=8)
    branch.apply_translation([0, 0, 0.5])  # 1 m along Z, base at 0: a Z-up export without our header
    leaf = trimesh.creation.box(extents=[0.05, 0.005, 0.3])  # a Y-up card, thin along Y, long along Z
    ours = trimesh.creation.cylinder(radius=0.03, height=0.8, sections=8)
    ours.apply_translation([0, 0, 0.4])
    folder = _folder_with(tmp_path, branch_00=(branch, "# exported by 3ds Max"),
                          branch_01=(leaf, "# Blender 4.1"),
                          branch_02=(ours, "# arboretum OBJ (Z up, metres)"))
    assert mesh_up_axis(folder / "branch_01.obj", np.asarray(leaf.vertices)) == "z"  # the shape guess would

    def extents(up):
        return {m.name: np.ptp(m.vertices, axis=0) for m in load_module_set(folder, up).modules}

    auto = extents("auto")
    assert np.argmax(auto["branch_00"]) == 1  # OBJ's usual Y up: the Z-up branch lies along Y
    assert np.argmax(auto["branch_01"]) == 1 and auto["branch_01"][2] < 0.01  # the card flat, not guessed up
    assert np.argmax(auto["branch_02"]) == 2  # our header says Z up
    z = extents("z")
    assert np.argmax(z["branch_00"]) == 2 and np.argmax(z["branch_02"]) == 2  # --modules-up z; header kept


def test_modules_up_needs_modules(tmp_path, capsys):
    ball = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    _write_obj(tmp_path / "c.obj", ball.vertices, ball.faces)
    code = main(["modules", "--crown", str(tmp_path / "c.obj"), "--out", str(tmp_path / "m.glb"), "--modules-up", "z"])
    assert code == 2 and "--modules-up applies to the files of --modules DIR only" in capsys.readouterr().err
