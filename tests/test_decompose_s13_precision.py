"""A refusal of a scan stored too coarsely names the cause as well as the symptom (session 13).

The coffee tree as a float32 PLY centred on UTM coordinates (500,000 m, 5,400,000 m) sits on a 0.5 m
grid: ``decompose`` refused it as "2 separate trunks" and never printed the precision note the docs
promise, since the note came after the decomposition (helper-103).
"""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.pointio import read_points
from arboretum_server.batch.tasks import decompose_scan
from arboretum_server.decompose.notes import refusal
from factories import float32_ply

UTM = np.array([500_000.0, 5_400_000.0, 300.0])


@pytest.fixture(scope="module")
def coffee() -> np.ndarray:
    return read_points(sample_scans()[0]).points


def test_decompose_says_the_grid_when_it_refuses(tmp_path, capsys, coffee):
    scan = float32_ply(tmp_path / "f32_utm.ply", coffee - coffee.mean(axis=0) + UTM)
    assert main(["decompose", str(scan)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "separate trunks" in err[0]
    assert "the file's precision may be why:" in err[0] and "are only 0.5 m apart" in err[0]
    assert "re-export it as float64" in err[0]


def test_a_build_worker_says_it_too(tmp_path, coffee):
    scan = float32_ply(tmp_path / "f32_utm.ply", coffee - coffee.mean(axis=0) + UTM)
    out = decompose_scan(str(scan), "ab" * 32, {"species": "unknown"})
    assert out.examples == ()
    assert "separate trunks" in out.error and "are only 0.5 m apart" in out.error


def test_a_fine_file_is_refused_as_before(tmp_path, capsys, coffee):
    near = coffee - coffee.mean(axis=0)  # float32 near the origin: 1e-7 m steps, no note
    scan = float32_ply(tmp_path / "two.ply", np.concatenate([near, near + [3.0, 0.0, 0.0]]))
    assert main(["decompose", str(scan)]) == 2
    err = capsys.readouterr().err.strip()
    assert "separate trunks" in err and "precision" not in err


def test_a_refusal_of_the_options_gets_no_precision_note(tmp_path, capsys, coffee):
    scan = float32_ply(tmp_path / "f32_utm.ply", coffee - coffee.mean(axis=0) + UTM)
    assert main(["decompose", str(scan), "--main", "200"]) == 2
    err = capsys.readouterr().err.strip()
    assert "main branches: 200 asked, at most 96" in err and "precision" not in err


def test_a_build_names_the_file_not_its_path_in_the_note(tmp_path, coffee):
    """The build's line names the path already, and a refusal is cut at 500 characters: with a long path
    the fix advice at the note's end was cut off (helper-106)."""
    folder = tmp_path / ("a-rather-long-folder-name-of-scans-" * 4)
    folder.mkdir()
    scan = float32_ply(folder / "f32_utm.ply", coffee - coffee.mean(axis=0) + UTM)
    out = decompose_scan(str(scan), "ab" * 32, {"species": "unknown"})
    assert str(folder) not in out.error and "'f32_utm.ply': coordinates stored as float32" in out.error
    assert out.error.endswith("re-export it as float64, or shifted near the origin")


def test_refusal_wording():
    assert refusal("x: refused", None) == "x: refused"
    assert refusal("x: refused", "coarse") == "x: refused; the file's precision may be why: coarse"
