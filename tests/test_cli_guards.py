"""`grow`, `synth`, `modules`, `render`: a user's mistake is one clear error (exit 2) before any work.

Each case here was found by a bug hunt: an output equal to an input overwrote it, an output path that
could not be written failed after all the work naming a temporary file, a negative seed or a huge
--lod / --sides / --density ended in a traceback or in gigabytes of memory.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from arboretum_library.cli import main
from arboretum_library.codec import save_record
from factories import make_hbl


@pytest.fixture(scope="module")
def hbl_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("guards") / "h.npz"
    save_record(path, make_hbl(np.random.default_rng(9), n_main=2, n_lobes=3))
    return path


@pytest.fixture
def no_work(monkeypatch):
    """Every command's long work fails the test if it starts: errors must come before it."""
    import arboretum_client.render_cli as render_cli
    import arboretum_server.grow.tree as grow_tree
    import arboretum_server.modules.cli as modules_cli
    import arboretum_server.synth.cli as synth_cli

    def fail(*args, **kwargs):
        raise AssertionError("the work started before the arguments were checked")

    monkeypatch.setattr(grow_tree, "grow_tree", fail)
    monkeypatch.setattr(synth_cli, "grow", fail)
    monkeypatch.setattr(modules_cli, "_grown", fail)
    monkeypatch.setattr(modules_cli, "_converted", fail)
    monkeypatch.setattr(render_cli, "read_input", fail)


def _error(argv, capsys) -> str:
    """The one-line error of ``argv`` (asserting exit 2, one line, no traceback)."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"arboretum {argv[0]}: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err and ".tmp" not in err
    return err


@pytest.mark.parametrize("argv, keep, words", [
    (["render", "h.npz", "--out", "h.npz"], "h.npz", r"--out h.npz: writes \.png files, not \.npz"),
    (["modules", "--crown", "c.glb", "--out", "c.glb"], "c.glb", "--out .*c.glb: is the input"),
    (["grow", "h.npz", "--out", "m.ply", "--skeleton", "m.ply"], "h.npz", "--skeleton .*m.ply: is also another output"),
    (["synth", "--out", "s.ply", "--mesh", "s.ply"], "h.npz", "--mesh .*s.ply: is also another output"),
    (["render", "h.npz", "--out", "r.jpg"], "h.npz", r"--out .*r.jpg: writes \.png files, not \.jpg"),
])
def test_an_output_never_replaces_an_input_or_another_output(tmp_path, hbl_file, capsys, no_work, monkeypatch,
                                                               argv, keep, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "h.npz").write_bytes(hbl_file.read_bytes())
    (tmp_path / "c.glb").write_bytes(b"glTF crown bytes")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    err = _error(argv, capsys)
    assert re.search(words, err), err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # nothing written, nothing lost


@pytest.mark.parametrize("argv, words", [
    (["render", "IN", "--out", "dirout"], "--out dirout: is a folder"),
    (["render", "IN", "--out", "afile/r.png"], "--out afile/r.png: afile is a file, not a folder"),
    (["grow", "IN", "--out", "afile/g.glb"], "--out afile/g.glb: afile is a file, not a folder"),
    (["grow", "IN", "--out", "g.glb", "--skeleton", "nodir/s.json"], "--skeleton nodir/s.json: the folder nodir"),
    (["synth", "--out", "afile/s.ply"], "--out afile/s.ply: afile is a file"),
    (["synth", "--out", "s.ply", "--truth", "afile/t.npz"], "--truth afile/t.npz: afile is a file"),
    (["synth", "--out", "s.ply", "--mesh", "nodir/m.glb"], "--mesh nodir/m.glb: the folder nodir does not"),
    (["modules", "--tree", "IN", "--out", "afile/m.glb"], "--out afile/m.glb: afile is a file"),
    (["grow", "dirout", "--out", "g.glb"], "HBL_OR_ASSEMBLY dirout: is a folder"),
    (["render", "dirout", "--out", "r.png"], "dirout: is a folder"),
    (["modules", "--tree", "dirout", "--out", "m.glb"], "--tree dirout: is a folder"),
    (["modules", "--crown", "png.xyz", "--out", "m.glb"], "--crown png.xyz: unsupported format '.xyz'"),
])
def test_path_errors_name_the_users_path_before_any_work(tmp_path, hbl_file, capsys, no_work, monkeypatch,
                                                        argv, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dirout").mkdir()
    (tmp_path / "afile").write_text("a file")
    (tmp_path / "png.xyz").write_bytes(b"\x89PNG\r\n")
    argv = [str(hbl_file) if a == "IN" else a for a in argv]
    err = _error(argv, capsys)
    assert re.search(words, err) and "module mesh" not in err, err


def test_a_crown_that_cannot_be_read_is_named_as_the_crown(tmp_path, capsys):
    (tmp_path / "c.obj").write_text("not an obj\n")
    err = _error(["modules", "--crown", str(tmp_path / "c.obj"), "--out", str(tmp_path / "m.glb")], capsys)
    assert "--crown" in err and "module mesh" not in err


@pytest.mark.parametrize("argv, words", [
    (["grow", "IN", "--out", "g.glb", "--seed", "-5"], "--seed must not be negative, got -5"),
    (["synth", "--out", "s.ply", "--seed", "-1"], "--seed must not be negative, got -1"),
    (["modules", "--tree", "IN", "--out", "m.glb", "--seed", "-1"], "--seed must not be negative"),
    (["grow", "IN", "--out", "g.glb", "--lod", "99"], "--lod must be 0 (full detail) to 16 (coarsest), got 99"),
    (["grow", "IN", "--out", "g.glb", "--lod", "-1"], "--lod must be 0"),
    (["synth", "--out", "s.ply", "--mesh", "m.glb", "--lod", "-1"], "--lod must be 0"),
    (["grow", "IN", "--out", "g.glb", "--sides", "100000"], "--sides must be 3 to 64, got 100000"),
    (["grow", "IN", "--out", "g.glb", "--sides", "2"], "--sides must be 3 to 64"),
    (["grow", "IN", "--out", "g.glb", "--leaf-density", "1000"], "--leaf-density must be a number >= 0 and <= 20"),
    (["grow", "IN", "--out", "g.glb", "--leaf-density", "nan"], "--leaf-density must be"),
    (["grow", "IN", "--out", "g.glb", "--density", "1000"], "--density must be a number > 0 and <= 20"),
    (["grow", "IN", "--out", "g.glb", "--density", "inf"], "--density must be"),
    (["grow", "IN", "--out", "g.glb", "--step", "nan"], "--step must be a number > 0"),
    (["grow", "IN", "--out", "g.glb", "--leaf-size", "-1"], "--leaf-size must be a number > 0"),
    (["grow", "IN", "--out", "g.glb", "--step", "1e-6"], "--step 1e-06 m is too fine for these lobes"),
    (["grow", "IN", "--out", "g.glb", "--step", "100"], "--step 100 m is larger than every lobe"),
    (["synth", "--out", "s.ply", "--noise", "nan"], "--noise must be a number >= 0 and <= 1"),
    # a reviewer's cases: 18.7 GB in 60 s, and minutes of scanning
    (["synth", "--out", "s.ply", "--nodes", "100000000"], "--nodes: must be 500..2,000,000"),
    (["synth", "--out", "s.ply", "--scanners", "100000"], "--scanners: must be 1..64"),
    (["synth", "--out", "s.ply", "--points", "100000000"], "--points: at most 5,000,000"),
    (["synth", "--out", "s.ply", "--noise", "-0.1"], "--noise must be"),
    (["synth", "--out", "s.ply", "--points", "1"], "--points: must be >= 200"),
])
def test_numbers_out_of_range_are_one_clear_error(tmp_path, hbl_file, capsys, no_work, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    err = _error([str(hbl_file) if a == "IN" else a for a in argv], capsys)
    assert words in err, err
    assert not any(tmp_path.iterdir())


def test_a_scan_left_too_small_to_decompose_is_not_written(tmp_path, capsys):
    """--leaf-off and a wide --missing-sector keep only part of the budget: under 200 points, an error."""
    out = tmp_path / "s.xyz"
    err = _error(["synth", "--out", str(out), "--points", "200", "--seed", "3", "--leaf-off",
                  "--missing-sector", "300", "--json"], capsys)
    assert "the scan kept only" in err and "--leaf-off, --missing-sector 300" in err and "needs 200" in err
    assert not out.exists()


def test_a_growth_too_big_for_memory_is_refused_naming_the_estimate(tmp_path, capsys, no_work):
    from arboretum_server.grow.attraction import default_step

    hbl = make_hbl(np.random.default_rng(9), n_main=2, n_lobes=8)
    save_record(tmp_path / "h.npz", hbl)
    d0 = default_step(hbl.lobes)
    err = _error(["grow", str(tmp_path / "h.npz"), "--out", str(tmp_path / "g.glb"), "--step", f"{d0 / 3.9:.6g}",
                  "--density", "20", "--leaf-density", "20"], capsys)
    assert "would grow about" in err and "over the limit of 1,500,000" in err and "GB of memory" in err


def test_the_size_estimate_bounds_what_grows(hbl_file):
    """``estimate_size`` is an upper estimate of the twig nodes, and follows the leaf density."""
    from arboretum_library.codec import load_record
    from arboretum_library.model import HBL
    from arboretum_server.grow.limits import LEAF_SHARE, estimate_size
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree

    hbl = load_record(hbl_file, HBL)
    opts = GrowOptions(density=2.0, leaf_density=3.0)
    nodes, leaves = estimate_size(hbl.lobes, opts)
    tree = grow_tree(hbl, opts, np.random.default_rng(1))
    assert 0.3 * nodes <= tree.twig_count <= 1.2 * nodes
    assert leaves == int(LEAF_SHARE * 3.0 * nodes) and len(tree.leaves.sizes) <= 1.2 * leaves


def test_coarsest_lod_and_a_big_step_still_grow(tmp_path, hbl_file, capsys):
    """--lod 16 meshes (it overflowed from 64 on); a step above the median lobe is a note, not an error."""
    from arboretum_library.codec import load_record
    from arboretum_library.model import HBL
    from arboretum_server.grow.attraction import equivalent_radius

    radii = sorted(equivalent_radius(lb) for lb in load_record(hbl_file, HBL).lobes)
    step = (radii[1] + radii[2]) / 2  # above the median lobe, below the largest
    assert main(["grow", str(hbl_file), "--out", str(tmp_path / "g.ply"), "--lod", "16", "--step", f"{step:.6g}",
                 "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["lod"] == 16 and "note: --step" in err and "few twigs will grow" in err


def test_thin_chains_takes_any_stride():
    from arboretum_server.mesh.chains import split_chains
    from arboretum_server.mesh.lod import thin_chains

    parents = np.r_[-1, np.arange(9)]  # one chain of 10 nodes
    chains = split_chains(parents, np.linspace(1.0, 0.1, 10))
    huge = thin_chains(chains, 1 << 70)
    assert huge.nodes.tolist() == [0, 9] and thin_chains(chains, 9).nodes.tolist() == [0, 9]


@pytest.mark.parametrize("argv", [["grow", "h.npz", "--out", "tree.obj"],
                                  ["synth", "--out", "s.ply", "--mesh", "tree.obj"]])
@pytest.mark.parametrize("foreign", ["tree.mtl", "tree_leaf.png"])
def test_a_foreign_obj_sidecar_is_refused_before_growth(tmp_path, hbl_file, capsys, no_work, monkeypatch,
                                                        argv, foreign):
    """The OBJ writer refuses a .mtl or texture it did not write; the CLIs ask it before growing (before:
    the refusal came after the whole growth)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "h.npz").write_bytes(hbl_file.read_bytes())
    (tmp_path / foreign).write_bytes(b"someone else's file\n")
    err = _error(argv, capsys)
    assert re.search(rf"{foreign}: exists and was not written by Arboretum", err), err
    assert (tmp_path / foreign).read_bytes() == b"someone else's file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["h.npz", foreign])
