"""``arboretum synth``: files, JSON summary, determinism, user errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from plyfile import PlyData

from arboretum_library.cli import main
from arboretum_library.truth import load_truth

BASE = [
    "synth",
    "--model",
    "guiding",
    "--species",
    "default",
    "--nodes",
    "8000",
    "--points",
    "3000",
]


def _ply(path):
    v = PlyData.read(str(path))["vertex"]
    pts = np.stack([v["x"], v["y"], v["z"]], axis=1)
    return pts, np.asarray(v["label"]), np.asarray(v["branch_id"])


def test_synth_writes_scan_and_truth(tmp_path, capsys):
    out, truth = tmp_path / "scan.ply", tmp_path / "truth.npz"
    assert main(BASE + ["--seed", "3", "--out", str(out), "--truth", str(truth), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    pts, labels, bids = _ply(out)
    tr = load_truth(truth)
    assert pts.shape == (3000, 3) and summary["points"] == 3000
    assert summary["wood_points"] == int((labels == 0).sum()) and (labels == 1).any()
    assert summary["nodes"] == tr.node_count and tr.model == "guiding" and tr.seed == 3
    assert set(np.unique(bids)) <= set(np.unique(tr.branch_id).tolist())
    assert np.isclose(summary["height"], np.ptp(tr.positions[:, 2]))


def test_same_seed_same_files(tmp_path, capsys):
    runs = []
    for name in ("a", "b"):
        out = tmp_path / f"{name}.ply"
        assert (
            main(
                BASE
                + [
                    "--seed",
                    "5",
                    "--out",
                    str(out),
                    "--leaf-off",
                    "--missing-sector",
                    "60",
                    "--json",
                ]
            )
            == 0
        )
        runs.append(_ply(out))
    capsys.readouterr()
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][2], runs[1][2])
    assert (runs[0][1] == 0).all()  # leaf-off


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--species", "oak-ish"], "unknown guiding preset"),
        (["--points", "0"], "--points"),
        (["--missing-sector", "400"], "--missing-sector"),
        (["--truth", "t.txt"], ".npz"),
    ],
)
def test_user_errors_are_one_line(tmp_path, capsys, extra, words):
    args = BASE + ["--out", str(tmp_path / "s.ply")] + extra
    if "--truth" in extra:
        args[-1] = str(tmp_path / "t.txt")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and "Traceback" not in err


def test_synth_harmonic_model(tmp_path, capsys):
    harmonic = pytest.importorskip("arboretum_server.synth.harmonic")
    if not hasattr(harmonic, "grow_species"):
        pytest.skip("the harmonic model is not built yet")
    out, truth = tmp_path / "h.ply", tmp_path / "h.npz"
    args = ["synth", "--model", "harmonic", "--species", "pine", "--seed", "2", "--points", "2500"]
    assert main(args + ["--out", str(out), "--truth", str(truth), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    pts, labels, bids = _ply(out)
    tr = load_truth(truth)
    assert pts.shape == (2500, 3) and tr.model == "harmonic" and summary["nodes"] == tr.node_count
    assert set(np.unique(bids)) <= set(np.unique(tr.branch_id).tolist())


def test_mesh_of_the_true_tree(tmp_path, capsys):
    """`--mesh` writes the truth as tubes and leaf cards: counts follow the truth, the GLB validates."""
    from arboretum_library.export.gltf_read import read_glb
    from arboretum_library.truth import load_truth
    from arboretum_server.mesh.scene import truth_mesh
    from test_export_gltf import validate

    args = ["synth", "--model", "harmonic", "--species", "ginkgo", "--seed", "2", "--points", "2000",
            "--out", str(tmp_path / "s.ply"), "--truth", str(tmp_path / "t.npz"), "--mesh", str(tmp_path / "m.glb")]
    assert main([*args, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    truth = load_truth(tmp_path / "t.npz")
    mesh = truth_mesh(truth)
    assert len(mesh.leaves.faces) == 2 * truth.leaf_count  # one two-triangle card per leaf
    assert summary["mesh_triangles"] == mesh.triangles
    assert np.allclose(mesh.leaves.positions.reshape(-1, 4, 3).mean(axis=1), truth.leaf_positions)
    # every tube is closed: with the UV-seam duplicates welded, each edge borders exactly two triangles
    _, weld = np.unique(np.round(mesh.tubes.positions, 9), axis=0, return_inverse=True)
    for c in np.unique(mesh.tubes.face_chain)[:50]:
        f = weld.reshape(-1)[mesh.tubes.faces[mesh.tubes.face_chain == c]]
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        assert (np.unique(e, axis=0, return_counts=True)[1] == 2).all()
    report = validate(tmp_path / "m.glb")
    assert report["issues"]["numErrors"] == 0
    assert sum(len(m.faces) for m in read_glb(tmp_path / "m.glb")) == mesh.triangles
    assert main([*args[:-1], str(tmp_path / "m.stl")]) == 2
    assert "--mesh" in capsys.readouterr().err
