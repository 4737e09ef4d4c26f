"""``arboretum modules``: crown mesh, HBL lobes or a grown tree in; instanced GLB / USD out; clear errors."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pygltflib
import pytest
import trimesh

from arboretum_library.assembly import Assembly
from arboretum_library.cli import main
from arboretum_library.codec import save_record
from arboretum_library.export.instanced import EXTENSION
from arboretum_library.model import HBL
from arboretum_server.grow.demo import demo_hbl
from arboretum_server.modules.meshio import save_obj
from arboretum_server.modules.shapes import tetrahedron_mesh


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("modules_cli")
    save_obj(d / "crown.obj", *tetrahedron_mesh([0, 0, 4.5], 6.5))
    save_record(d / "hbl.npz", demo_hbl(np.random.default_rng(0), n_lobes=8))
    save_record(d / "assembly.npz", Assembly())
    hbl = demo_hbl(np.random.default_rng(0), n_lobes=3)
    lobes = tuple(dataclasses.replace(lb, branch=-1) for lb in hbl.lobes)
    save_record(d / "nobranch.npz", HBL(root=hbl.root, branches=(), lobes=lobes))
    trimesh.PointCloud(np.random.default_rng(1).normal(size=(500, 3))).export(d / "cloud.ply")
    return d


def _run(argv, capsys) -> dict:
    assert main(argv + ["--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_crown_to_instanced_glb(tmp_path, files, capsys):
    out = tmp_path / "t.glb"
    s = _run(["modules", "--crown", str(files / "crown.obj"), "--out", str(out), "--seed", "1"], capsys)
    assert s["bytes"] == out.stat().st_size and s["source"] == "crown"
    gltf = pygltflib.GLTF2().load(str(out))
    counts = [gltf.accessors[n.extensions[EXTENSION]["attributes"]["TRANSLATION"]].count for n in gltf.nodes]
    assert sum(counts) == s["modules_placed"] > 50 and len(counts) == s["types_used"]
    assert s["compression"] == pytest.approx(s["flat_bytes"] / s["bytes"]) and s["compression"] > 5
    assert sum(s["constraints"]["violations"].values()) == 0 and s["constraints"]["reached_fraction"] > 0.85
    out2 = tmp_path / "again.glb"
    _run(["modules", "--crown", str(files / "crown.obj"), "--out", str(out2), "--seed", "1"], capsys)
    assert out.read_bytes() == out2.read_bytes()


def test_crown_types_and_plain_nodes(tmp_path, files, capsys):
    out = tmp_path / "p.glb"
    s = _run(["modules", "--crown", str(files / "crown.obj"), "--out", str(out), "--types", "2",
              "--plain-nodes"], capsys)
    gltf = pygltflib.GLTF2().load(str(out))
    assert not gltf.extensionsUsed and len(gltf.nodes) == s["modules_placed"]
    assert s["types_used"] <= 3  # two branch types and the trunk


def test_assembly_hbl_to_usd(tmp_path, files, capsys):
    from pxr import Usd, UsdGeom

    out = tmp_path / "t.usda"
    s = _run(["modules", "--assembly", str(files / "hbl.npz"), "--out", str(out)], capsys)
    stage = Usd.Stage.Open(str(out))  # keep the stage alive while its prims are used
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Tree/Instancer"))
    assert len(pi.GetProtoIndicesAttr().Get()) == s["modules_placed"] > 1
    root = demo_hbl(np.random.default_rng(0), n_lobes=8).branches[0].points[0]
    np.testing.assert_allclose(pi.GetPositionsAttr().Get()[0], root, atol=1e-6)  # the trunk stands there


def test_tree_conversion(tmp_path, files, capsys):
    out = tmp_path / "t.usdc"
    s = _run(["modules", "--tree", str(files / "hbl.npz"), "--out", str(out), "--types", "8"], capsys)
    assert s["types_used"] == 8 and s["modules_placed"] > 100
    assert 0 < s["chamfer_fraction"] < 0.002 and s["compression"] > 5


@pytest.mark.parametrize("argv, message", [
    (["--crown", "missing.obj", "--out", "OUT/t.glb"], "no such file"),
    (["--crown", "CROWN", "--out", "OUT/t.fbx"], "unknown format '.fbx'"),
    (["--crown", "CROWN", "--out", "OUT/t.usda", "--plain-nodes"], "--plain-nodes applies to .glb only"),
    (["--crown", "CROWN", "--out", "OUT/t.glb", "--modules", "OUT/nothing"], "not a folder"),
    (["--tree", "CROWN", "--out", "OUT/t.glb"], "not a readable .npz"),
    (["--crown", "CROWN", "--out", "OUT/t.glb", "--types", "0"], "--types must be >= 1"),
    (["--assembly", "ASSEMBLY", "--out", "OUT/t.glb"], "needs --library LIB"),
    (["--crown", "CLOUD", "--out", "OUT/t.glb"], "cloud.ply: has no triangles"),
    (["--assembly", "NOBRANCH", "--out", "OUT/t.glb"], "nobranch.npz: has no branches"),
    (["--tree", "HBL", "--out", "OUT/t.glb", "--modules", "/no/such/folder"], "--modules applies to --crown"),
    (["--tree", "HBL", "--out", "OUT/t.glb", "--modules", "OUT"], "--modules applies to --crown"),
])
def test_user_errors_are_one_line(tmp_path, files, capsys, argv, message):
    names = {"CROWN": "crown.obj", "ASSEMBLY": "assembly.npz", "CLOUD": "cloud.ply", "NOBRANCH": "nobranch.npz",
             "HBL": "hbl.npz"}
    argv = [str(files / names[a]) if a in names else a.replace("OUT", str(tmp_path)) for a in argv]
    assert main(["modules", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not list(tmp_path.glob("t.*"))


def test_assembly_record_with_library(tmp_path, capsys):
    from arboretum_library.assembly import Placement
    from arboretum_library.store import Library
    from factories import make_example

    example = make_example(np.random.default_rng(8), id="ex-0", n_lobes=4)
    with Library.open(tmp_path / "lib", create=True) as lib:
        lib.add(example)
    T = np.eye(4)
    T[:3, 3] = [5.0, 0.0, 0.0]
    save_record(tmp_path / "a.npz", Assembly(placements=(Placement("p", "ex-0", T),)))
    out = tmp_path / "t.glb"
    s = _run(["modules", "--assembly", str(tmp_path / "a.npz"), "--library", str(tmp_path / "lib"),
              "--out", str(out)], capsys)
    gltf = pygltflib.GLTF2().load(str(out))
    assert sum(gltf.accessors[n.extensions[EXTENSION]["attributes"]["TRANSLATION"]].count
               for n in gltf.nodes) == s["modules_placed"] > 1
    trunk = next(n for n in gltf.nodes if gltf.meshes[n.mesh].name.startswith("trunk"))
    acc = gltf.accessors[trunk.extensions[EXTENSION]["attributes"]["TRANSLATION"]]
    view = gltf.bufferViews[acc.bufferView]
    t = np.frombuffer(gltf.binary_blob(), np.float32, 3, view.byteOffset)
    root = example.structure.branches[0].points[0] + [5.0, 0.0, 0.0]
    np.testing.assert_allclose(t, [root[0], root[2], -root[1]], atol=1e-5)  # Y up in glTF
