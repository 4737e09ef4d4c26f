"""``decompose`` and ``library build`` on a LAS file read Z up though its shape says Y up (session 20):
LAS is Z up by its format, so ``--up auto`` no longer guesses it (a wall or returns under the ground
turned guesses), and a note, or the refusal, names the ``--up`` that reads it the shape's way."""

from __future__ import annotations

import json

import numpy as np

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import ReadOptions, read_points
from arboretum_server.decompose.notes import las_doubt
from factories import las_file as _las

COFFEE = sample_scans()[0]
SMALL = ["--points", "3000", "--main", "3", "--lobes", "6"]


def test_a_y_up_las_gets_the_note_and_decomposes_with_up_y(tmp_path, capsys):
    coffee = read_points(COFFEE, ReadOptions(up="z")).points
    lying = _las(tmp_path / "coffee_y.las", zup_to_yup(coffee))
    upright = _las(tmp_path / "coffee.las", coffee)
    code = main(["decompose", str(lying), "--json", *SMALL])
    said = capsys.readouterr()
    text = said.out if code == 0 else said.err
    assert "the LAS file is read Z up, as its format defines, but its shape says y " in text
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


def test_an_upside_down_las_refused_or_noted_names_z_down(tmp_path, capsys):
    coffee = read_points(COFFEE, ReadOptions(up="z")).points
    h, foot = float(np.ptp(coffee[:, 2])), coffee[np.argmin(coffee[:, 2])]
    rng = np.random.default_rng(0)
    a, r = rng.uniform(0, 2 * np.pi, 8000), 1.5 * h * np.sqrt(rng.uniform(0, 1, 8000))
    disc = np.c_[foot[0] + r * np.cos(a), foot[1] + r * np.sin(a), foot[2] + rng.normal(0, 0.003, 8000)]
    down = _las(tmp_path / "down.las", np.r_[coffee, disc] * [1, -1, -1])
    code = main(["decompose", str(down), "--json", *SMALL])
    said = capsys.readouterr()
    assert "its shape says z-down" in (said.out if code == 0 else said.err)
    assert "pass --up z-down" in (said.out if code == 0 else said.err)
    assert main(["decompose", str(down), "--up", "z-down", "--json", *SMALL]) == 0
    assert json.loads(capsys.readouterr().out)["stats"]["main_branches"] == 3
