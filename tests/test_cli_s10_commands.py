"""``decompose``, ``library build`` and ``photos`` (session 10): a sparse cloud decomposes with
``--min-points``, each wrong option gets its own message, seeds are checked before any work, counts
of one are singular."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.assets import assets_dir
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.pointio import write_points
from arboretum_library.store import Library


def _err_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture(scope="module")
def sparse(tmp_path_factory) -> Path:
    """120 points of the real coffee tree: as many as a photo reconstruction keeps on a tree."""
    out = tmp_path_factory.mktemp("sparse") / "s120.ply"
    scan = assets_dir() / "scans" / "01_rtwig_coffeetree" / "01_rtwig_coffeetree.xyz"
    assert main(["scan", "convert", str(scan), str(out), "--max-points", "120"]) == 0
    return out


@pytest.fixture
def cloud(tmp_path) -> Path:
    rng = np.random.default_rng(3)
    return write_points(tmp_path / "c.xyz", np.c_[rng.normal(0, 0.3, (500, 2)), rng.uniform(0, 4, 500)])


# ---------------------------------------------------------------- decompose --min-points


def test_a_sparse_cloud_decomposes_with_min_points(sparse, tmp_path, capsys):
    lib = tmp_path / "L"
    assert main(["decompose", str(sparse), "--library", str(lib)]) == 2
    err = _err_line(capsys)
    assert "120 usable points, fewer than --min-points 200" in err and not lib.exists()
    args = ["decompose", str(sparse), "--min-points", "100", "--main", "3", "--lobes", "8", "--library", str(lib)]
    assert main([*args, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["stats"]["points"], data["stats"]["main_branches"], data["stats"]["lobes"]) == (120, 3, 8)
    assert data["options"]["min_points"] == 100 and len(data["stored"]) == 3
    with Library.open(lib, readonly=True) as L:
        assert sorted(L.ids()) == sorted(data["stored"])


def test_min_points_below_one_lobe_is_refused_before_the_scan_is_read(tmp_path, capsys):
    lib = tmp_path / "L"
    assert main(["decompose", str(tmp_path / "none.xyz"), "--min-points", "9", "--library", str(lib)]) == 2
    assert _err_line(capsys) == "arboretum decompose: error: --min-points must be at least 10 (the points of one lobe), got 9\n"
    assert not lib.exists()


def test_points_below_a_given_min_points_is_refused(cloud, capsys):
    assert main(["decompose", str(cloud), "--min-points", "100", "--points", "50"]) == 2
    assert "--points 50 leaves too few points to decompose a tree (at least 100" in _err_line(capsys)


def test_one_example_is_singular(sparse, capsys):
    assert main(["decompose", str(sparse), "--min-points", "100", "--main", "1", "--lobes", "2"]) == 0
    out = capsys.readouterr().out
    assert "\n1 example made (not stored: no --library given)\n" in out


# ---------------------------------------------------------------- one message per option


@pytest.mark.parametrize("extra, message", [
    (["--points", "-1"], "--points must not be negative (0: all), got -1"),
    (["--height", "nan"], "--height must be a finite number >= 0 (0: keep the scan's units), got nan"),
    (["--height", "-2"], "--height must be a finite number >= 0 (0: keep the scan's units), got -2.0"),
])
def test_decompose_names_only_the_wrong_option(cloud, capsys, extra, message):
    assert main(["decompose", str(cloud), *extra]) == 2
    assert _err_line(capsys) == f"arboretum decompose: error: {message}\n"


@pytest.mark.parametrize("extra, message", [
    (["--points", "-1"], "--points must not be negative (0: all), got -1"),
    (["--height", "-2"], "--height must be a finite number >= 0 (0: keep the scan's units), got -2.0"),
    (["--height", "nan"], "--height must be a finite number >= 0 (0: keep the scan's units), got nan"),
])
def test_build_names_only_the_wrong_option(cloud, tmp_path, capsys, extra, message):
    lib = tmp_path / "B"
    assert main(["library", "build", str(cloud), "--library", str(lib), *extra]) == 2
    assert _err_line(capsys) == f"arboretum library: error: {message}\n" and not lib.exists()


# ---------------------------------------------------------------- library build: counts of one


def _build_data(**counts) -> dict:
    d = {"library": "L", "scans": 1, "added": 1, "examples_added": 1, "redone": 0, "skipped": 0,
         "duplicate": 1, "failed": 0, "wall_seconds": 2.0, "worker_seconds": 1.0, "workers": 1,
         "cluster": "LocalCluster", "records": [], "ignored": [], "library_kept": True,
         "report": {"markdown": "r.md"}}
    return {**d, **counts}


def test_build_summary_is_singular_for_one():
    from arboretum_server.batch.cli import _text
    from arboretum_server.batch.report import markdown

    line = _text(_build_data()).splitlines()[0]
    assert line == ("L: 1 scan added (1 example), 0 already there, 1 duplicate, 0 failed, in 2.0 s "
                    "on 1 worker (LocalCluster)")
    line = _text(_build_data(added=2, examples_added=9, duplicate=0, workers=2)).splitlines()[0]
    assert "2 scans added (9 examples)" in line and "0 duplicates" in line and "on 2 workers" in line
    md = markdown(_build_data(), {})
    assert "- cluster: LocalCluster, 1 worker\n" in md and "1 added (1 example), 0 already in the library, 1 duplicate," in md


# ---------------------------------------------------------------- photos: checked before any work


@pytest.fixture
def images(tmp_path) -> Path:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for k in range(3):
        (folder / f"{k}.png").write_bytes(b"")  # never read: the arguments are refused first
    return folder


@pytest.mark.parametrize("source, extra, words", [
    ("images", ["--seed", "-1"], "--seed must not be negative, got -1"),
    ("model", ["--seed", "-3"], "--seed must not be negative, got -3"),
    ("images", ["--seed", str(2 ** 31)], f"--seed must be at most {2 ** 31 - 1} (COLMAP's largest), got {2 ** 31}"),
    ("images", ["--out", "missing/x.ply"], "the folder"),
    ("images", ["--out", "x.glb"], "writes .ply or .xyz or .txt or .npy files, not .glb"),
])
def test_photos_arguments_are_checked_before_any_work(images, tmp_path, capsys, monkeypatch, source, extra, words):
    import arboretum_server.photos.colmap_import as colmap_import
    import arboretum_server.photos.reconstruct as reconstruct

    def never(*a, **k):
        raise AssertionError("work started")

    monkeypatch.setattr(reconstruct, "reconstruct", never)
    monkeypatch.setattr(colmap_import, "read_model", never)
    monkeypatch.chdir(tmp_path)
    where = [str(images)] if source == "images" else ["--colmap-model", str(tmp_path / "model")]
    out = extra[1] if extra[0] == "--out" else "x.ply"
    flags = extra if extra[0] != "--out" else []
    assert main(["photos", *where, "--out", out, *flags]) == 2
    assert words in _err_line(capsys)


def test_photos_large_seed_is_fine_without_colmap(tmp_path, capsys, monkeypatch):
    """Only COLMAP's seeds are C ints: importing a model takes any seed numpy takes."""
    import arboretum_server.photos.colmap_import as colmap_import

    seen = []

    def read_model(path):
        seen.append(path)
        raise InputError("stop here")

    monkeypatch.setattr(colmap_import, "read_model", read_model)
    assert main(["photos", "--colmap-model", str(tmp_path / "m"), "--out", str(tmp_path / "x.ply"),
                 "--seed", str(2 ** 40)]) == 2
    assert "stop here" in _err_line(capsys) and seen == [str(tmp_path / "m")]
