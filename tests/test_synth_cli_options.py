"""``arboretum synth``: options that would do nothing are refused before any work; species defaults."""

from __future__ import annotations

import json

import pytest

import arboretum_server.synth.cli as synth_cli
from arboretum_library.cli import main


@pytest.mark.parametrize("argv, message", [
    (["--model", "harmonic"], "--model harmonic needs --species NAME, one of: apple, birch, cherry, "
                              "eucalyptus, ginkgo, oak, pine, walnut"),
    (["--model", "harmonic", "--species", "oak", "--nodes", "9000"],
     "--nodes 9000: sets the guiding model's graph; the harmonic model has none"),
    (["--model", "harmonic", "--species", "oak", "--lod", "9"],
     "--lod 9: sets the level of detail of --mesh; give --mesh too"),
    (["--lod", "0"], "--lod 0: sets the level of detail of --mesh; give --mesh too"),
])  # fmt: skip
def test_options_that_would_do_nothing_are_one_line_errors(argv, message, tmp_path, capsys, monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("the tree started growing before the arguments were checked")

    monkeypatch.setattr(synth_cli, "grow", fail)
    assert main(["synth", *argv, "--out", str(tmp_path / "s.ply")]) == 2
    err = capsys.readouterr().err
    assert err == f"arboretum synth: error: {message}\n"
    assert list(tmp_path.iterdir()) == []


def test_guiding_default_species_and_lod_with_mesh(tmp_path, capsys):
    out, mesh = tmp_path / "s.ply", tmp_path / "m.ply"
    argv = ["synth", "--nodes", "3000", "--points", "1000", "--out", str(out), "--json"]
    assert main(argv + ["--mesh", str(mesh), "--lod", "16"]) == 0
    coarse = json.loads(capsys.readouterr().out)
    assert main(argv + ["--mesh", str(mesh)]) == 0
    full = json.loads(capsys.readouterr().out)
    assert coarse["species"] == full["species"] == "default" and coarse["model"] == "guiding"
    assert coarse["nodes"] == full["nodes"] and 0 < coarse["mesh_triangles"] < full["mesh_triangles"]
