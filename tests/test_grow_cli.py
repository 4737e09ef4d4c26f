"""``arboretum grow``: formats by extension, --json summary, skeleton, determinism, clear errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from plyfile import PlyData

from arboretum_library.cli import main
from arboretum_library.codec import load_record, save_record
from arboretum_library.errors import InputError
from arboretum_library.model import HBL
from factories import make_hbl


@pytest.fixture(scope="module")
def hbl_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("hbl") / "tree.npz"
    save_record(path, make_hbl(np.random.default_rng(9), n_main=2, n_lobes=3))
    return path


def test_save_load_round_trip(hbl_file):
    h = load_record(hbl_file, HBL)
    ref = make_hbl(np.random.default_rng(9), n_main=2, n_lobes=3)
    assert len(h.branches) == len(ref.branches) and len(h.lobes) == len(ref.lobes)
    assert np.array_equal(h.lobes[1].hull_faces, ref.lobes[1].hull_faces)
    assert np.array_equal(h.branches[-1].points, ref.branches[-1].points)


def test_grow_glb_with_json_and_skeleton(tmp_path, hbl_file, capsys):
    out, skel = tmp_path / "t.glb", tmp_path / "s.json"
    code = main(["grow", str(hbl_file), "--out", str(out), "--seed", "3", "--skeleton", str(skel), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["twig_nodes"] > 100 and summary["triangles"] > 1000
    assert summary["bytes"] == out.stat().st_size
    s = json.loads(skel.read_text())
    assert s["nodes"] == summary["nodes"] and len(s["radii"]) == summary["nodes"]
    again = tmp_path / "t2.glb"
    main(["grow", str(hbl_file), "--out", str(again), "--seed", "3"])
    assert again.read_bytes() == out.read_bytes()  # same seed, same file


def test_grow_obj_ply_and_skeleton_ply(tmp_path, hbl_file):
    assert main(["grow", str(hbl_file), "--out", str(tmp_path / "t.obj"), "--lod", "1"]) == 0
    assert (tmp_path / "t.mtl").exists() and (tmp_path / "t_leaf.png").stat().st_size > 1000
    assert main(["grow", str(hbl_file), "--out", str(tmp_path / "t.ply"),
                 "--skeleton", str(tmp_path / "s.ply")]) == 0
    ply = PlyData.read(str(tmp_path / "s.ply"))
    assert ply["edge"].count == ply["vertex"].count - 1


@pytest.mark.parametrize("argv, message", [
    (["--out", "x.fbx"], "unknown format '.fbx'"),
    (["--out", "x.glb", "--skeleton", "s.txt"], "use .json or .ply"),
    (["--out", "/no/such/dir/x.glb"], "does not exist"),
])
def test_user_errors_are_one_line(tmp_path, hbl_file, capsys, argv, message):
    assert main(["grow", str(hbl_file), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_missing_or_wrong_file(tmp_path, capsys):
    assert main(["grow", str(tmp_path / "none.npz"), "--out", str(tmp_path / "x.glb")]) == 2
    assert "no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a readable .npz"):
        load_record(bad, HBL)


def test_branch_radii_flag(tmp_path, hbl_file, capsys):
    """--branch-radii hbl keeps the HBL's trunk radius; pipe sums every tip up to the root."""
    trunk = {}
    for mode in ("hbl", "pipe"):
        assert main(["grow", str(hbl_file), "--out", str(tmp_path / f"{mode}.ply"), "--branch-radii", mode,
                     "--json"]) == 0
        trunk[mode] = json.loads(capsys.readouterr().out)["trunk_radius"]
    assert trunk["hbl"] == pytest.approx(load_record(hbl_file, HBL).branches[0].radii[0], rel=1e-12)
    assert trunk["pipe"] != pytest.approx(trunk["hbl"], rel=1e-3)


def test_grow_an_assembly_against_its_library(tmp_path, capsys):
    """`arboretum grow` takes a saved Assembly with --library, as issue 5 specifies (HBL_OR_ASSEMBLY)."""
    import json

    from arboretum_library.assembly import Assembly, Placement
    from arboretum_library.cli import main
    from arboretum_library.codec import save_record
    from arboretum_library.geometry import make_transform
    from arboretum_library.store import Library
    from factories import make_example

    rng = np.random.default_rng(5)
    lib = Library.open(tmp_path / "lib", create=True)
    ids = [lib.add(make_example(rng, id=f"ex{i}", n_lobes=3)) for i in range(2)]
    lib.close()
    asm = Assembly(tuple(Placement(f"p{i}", e, make_transform(t=[3.0 * i, 0, 0])) for i, e in enumerate(ids)))
    path = save_record(tmp_path / "session.npz", asm)
    out = tmp_path / "tree.glb"
    assert main(["grow", str(path), "--library", str(tmp_path / "lib"), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["lobes"] == 6 and out.read_bytes()[:4] == b"glTF"
    assert main(["grow", str(path), "--out", str(out)]) == 2
    assert "needs --library" in capsys.readouterr().err
