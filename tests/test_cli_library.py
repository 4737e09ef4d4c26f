"""``arboretum library ...`` through ``arboretum_library.cli.main``: exact JSON, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arboretum_library.cli import main
from arboretum_library.store import Library
from factories import make_example


@pytest.fixture
def lib_path(tmp_path):
    path = tmp_path / "lib"
    specs = [("oak-1", "oak", 7, True), ("apple-1", "apple", 2, True), ("apple-2", "apple", 7, False)]
    with Library.open(path, create=True, fsync=False) as lib:
        for i, (id_, species, lobes, curved) in enumerate(specs):
            lib.add(make_example(np.random.default_rng(i), id=id_, n_lobes=lobes, curved=curved, species=species))
    return path


def _json(capsys, *argv) -> dict:
    assert main(["library", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_info_and_list(lib_path, capsys):
    info = _json(capsys, "info", lib_path)
    size = sum(f.stat().st_size for f in (lib_path / "examples").glob("*/*"))
    assert info == {"path": str(lib_path), "schema": 1, "examples": 3, "size_bytes": size,
                    "species": {"apple": 2, "oak": 1},
                    "tags": {"curved": 2, "dense": 2, "sparse": 1, "straight": 1}}
    listed = _json(capsys, "list", lib_path)
    assert listed["count"] == 3
    assert [(r["id"], r["species"], r["lobes"], r["tags"]) for r in listed["examples"]] == [
        ("apple-1", "apple", 2, ["curved", "sparse"]), ("apple-2", "apple", 7, ["dense", "straight"]),
        ("oak-1", "oak", 7, ["curved", "dense"])]


def test_search_and_show(lib_path, capsys):
    out = _json(capsys, "search", lib_path, "curved", "dense")
    assert [(h["id"], h["score"], h["matched"]) for h in out["hits"]] == [
        ("oak-1", 1.0, ["curved", "dense"]), ("apple-1", 0.5, ["curved"]), ("apple-2", 0.5, ["dense"])]
    out = _json(capsys, "search", lib_path, "curved", "--species", "apple", "--limit", "5")
    assert [h["id"] for h in out["hits"]] == ["apple-1"] and out["species"] == "apple"
    shown = _json(capsys, "show", lib_path, "apple-2")
    ex = make_example(np.random.default_rng(2), id="apple-2", n_lobes=7, species="apple")
    assert shown["lobes"] == 7 and shown["branches"] == 8 and shown["points"] == 200
    assert shown["descriptors"]["curvature"] == ex.descriptors.curvature
    assert shown["source_sha256"] == ex.provenance.source_sha256
    assert shown["parameters"] == {"N_m": 10, "K": 12, "alpha": 0.1}


def test_delete_export_import(lib_path, tmp_path, capsys):
    assert _json(capsys, "delete", lib_path, "oak-1") == {"deleted": "oak-1", "examples": 2}
    archive = tmp_path / "lib.tar"
    out = _json(capsys, "export", lib_path, archive)
    assert out == {"archive": str(archive), "examples": 2, "size_bytes": archive.stat().st_size}
    report = _json(capsys, "import", archive, tmp_path / "new")
    assert report == {"added": ["apple-1", "apple-2"], "replaced": [], "skipped": [], "renamed": {}}
    report = _json(capsys, "import", archive, tmp_path / "new", "--on-conflict", "rename")
    assert report["renamed"] == {"apple-1": "apple-1-0001", "apple-2": "apple-2-0001"}
    assert _json(capsys, "info", tmp_path / "new")["examples"] == 4


def test_text_output(lib_path, capsys):
    assert main(["library", "search", str(lib_path), "curved", "dense"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["id", "species", "lobes", "curv.", "tags"]
    assert [ln.split()[0] for ln in lines[1:]] == ["oak-1", "apple-1", "apple-2"]
    assert lines[1].endswith("score 1.00: curved dense") and lines[3].endswith("score 0.50: dense")
    assert main(["library", "info", str(lib_path)]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[:2] == ["examples:", "3"]


def test_user_mistakes_exit_2_with_one_line(lib_path, tmp_path, capsys):
    (tmp_path / "junk.tar").write_bytes(b"not an archive" * 50)
    cases = [(["import", tmp_path / "junk.tar", tmp_path / "x"], "not a readable archive"),
             (["search", lib_path, "x", "--limit", "0"], "--limit must be at least 1"),
             (["list", tmp_path], "not an Arboretum library"),
             (["info", tmp_path / "missing"], "does not exist"),
             (["show", lib_path, "nope"], "no example 'nope'"),
             (["delete", lib_path, "nope"], "no example 'nope'"),
             (["import", tmp_path / "none.tar", tmp_path / "x"], "does not exist")]
    for argv, message in cases:
        assert main(["library", *map(str, argv)]) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("arboretum library: error:") and message in lines[0]
    assert not (tmp_path / "x").exists()
