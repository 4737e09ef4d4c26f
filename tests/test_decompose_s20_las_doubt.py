"""``decompose`` and ``library build`` on a LAS file read Z up though its shape says Y up (session 20):
LAS is Z up by its format, so ``--up auto`` no longer guesses it (a wall or returns under the ground
turned guesses), and a note, or the refusal, names the ``--up`` that reads it the shape's way."""

from __future__ import annotations

import json

import laspy
import numpy as np

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import ReadOptions, read_points
from arboretum_server.decompose.notes import las_doubt

COFFEE = sample_scans()[0]
SMALL = ["--points", "3000", "--main", "3", "--lobes", "6"]


def _las(path, pts: np.ndarray):
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([1e-4, 1e-4, 1e-4]), pts.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))
    return path


def test_a_y_up_las_gets_the_note_and_decomposes_with_up_y(tmp_path, capsys):
    coffee = read_points(COFFEE, ReadOptions(up="z")).points
    lying = _las(tmp_path / "coffee_y.las", zup_to_yup(coffee))
    upright = _las(tmp_path / "coffee.las", coffee)
    code = main(["decompose", str(lying), "--json", *SMALL])
    said = capsys.readouterr()
    text = said.out if code == 0 else said.err
    assert "the LAS file is read Z up, as its format defines, but its shape looks y up" in text
    assert "pass --up y" in text
    assert main(["decompose", str(lying), "--up", "y", "--json", *SMALL]) == 0
    by_hand = json.loads(capsys.readouterr().out)
    assert by_hand["stats"]["main_branches"] == 3 and not any("LAS" in n for n in by_hand["notes"])
    assert main(["decompose", str(upright), "--json", *SMALL]) == 0
    assert not any("LAS" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_las_doubt_only_for_las_read_z_up_by_auto(tmp_path):
    coffee = read_points(COFFEE, ReadOptions(up="z")).points
    lying = read_points(_las(tmp_path / "c.laz", zup_to_yup(coffee)))
    assert lying.up_axis == "z"
    note = las_doubt(lying, "auto", build=True)
    assert note is not None and note.endswith("decompose it alone with --up y")
    assert las_doubt(lying, "z") is None  # the user said Z
    ply = read_points(COFFEE, ReadOptions(up="z"))
    assert las_doubt(ply, "auto") is None  # not a LAS file
    assert las_doubt(read_points(_las(tmp_path / "u.las", coffee)), "auto") is None  # its shape agrees
