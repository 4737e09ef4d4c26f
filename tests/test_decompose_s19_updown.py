"""``arboretum decompose`` and ``library build`` on a scan written upside down (session 19): with ground
at its top ``--up auto`` turns it the right way up and says so; without ground it is read as written and
a note, or the refusal, says it may be upside down (a spruce's skirt or a pole beside a tree look the
same, helper-136); ``--up z-down`` says it by hand."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.pointio import ReadOptions, read_points, write_points
from arboretum_library.pointio_up import turn_from_zup
from arboretum_server.decompose.notes import up_guess_flat, upside_down_doubt, upside_down_note

COFFEE = sample_scans()[0]
SMALL = ["--points", "3000", "--main", "3", "--lobes", "6"]


def _run(capsys, *argv: str, code: int = 0) -> dict:
    assert main(["decompose", *map(str, argv), "--json", *SMALL]) == code
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def coffee():
    """The coffee tree (Z up) on a ground disc 1.5 heights in radius round its trunk base."""
    pts = read_points(COFFEE, ReadOptions(up="z")).points
    h, foot = float(np.ptp(pts[:, 2])), pts[np.argmin(pts[:, 2])]
    rng = np.random.default_rng(0)
    a, r = rng.uniform(0, 2 * np.pi, 8000), 1.5 * h * np.sqrt(rng.uniform(0, 1, 8000))
    disc = np.stack([foot[0] + r * np.cos(a), foot[1] + r * np.sin(a), foot[2] + rng.normal(0, 0.003, 8000)], axis=1)
    return pts, np.concatenate([pts, disc])


@pytest.mark.parametrize("way", ["z-down", "y-down"])
def test_an_upside_down_scan_on_ground_decomposes_as_the_upright_one(tmp_path, capsys, coffee, way):
    upright_file, down = tmp_path / "coffee.xyz", tmp_path / f"coffee_{way}.xyz"
    write_points(upright_file, coffee[1])
    write_points(down, turn_from_zup(coffee[1], way))
    upright = _run(capsys, upright_file, "--up", "z")
    turned = _run(capsys, down)
    assert turned["notes"][0] == (f"--up auto found the file upside down (its ground at the top) and turned it "
                                  f"the right way up (--up {way}); to read it as written, pass --up {way[0]}")
    assert not any("upside down" in n for n in upright["notes"])
    for key in ("main_branches", "lobes", "height", "ground_removed"):
        assert turned["stats"][key] == pytest.approx(upright["stats"][key], rel=1e-6), key
    assert turned["stats"]["ground_removed"] > 4000
    by_hand = _run(capsys, down, "--up", way)
    assert not any("upside down" in n for n in by_hand["notes"])  # the user said so: nothing to tell
    assert by_hand["stats"]["height"] == pytest.approx(upright["stats"]["height"], rel=1e-6)


def test_upside_down_without_ground_is_read_as_written_and_doubted(tmp_path, capsys, coffee):
    down = tmp_path / "coffee_down.xyz"
    write_points(down, turn_from_zup(coffee[0], "z-down"))
    data = _run(capsys, down, code=2)  # no trunk base at the crown top: refused, and the refusal says why
    assert data["error"].endswith("the tree may stand upside down as read (--up z): its top is trunk-like over a "
                                  "much wider foot and no ground tells which way is up; if the file is upside "
                                  "down, pass --up z-down")
    fixed = _run(capsys, down, "--up", "z-down")  # as the message says
    assert fixed["stats"]["main_branches"] == 3 and not any("upside down" in n for n in fixed["notes"])


def test_the_users_z_down_on_an_upright_file_is_doubted(tmp_path, capsys, coffee):
    upright = tmp_path / "coffee.xyz"
    write_points(upright, coffee[0])
    out = main(["decompose", str(upright), "--up", "z-down", "--json", *SMALL])
    data = json.loads(capsys.readouterr().out)
    said = data["error"] if out else " ".join(data["notes"])
    assert "the tree may stand upside down as read (--up z-down)" in said and "pass --up z" in said


def test_the_way_up_notes():
    assert upside_down_note("auto", "z") is None
    assert upside_down_note("z-down", "z-down") is None
    assert upside_down_note("auto", "y-down").endswith("(--up y-down); to read it as written, pass --up y")
    assert upside_down_note("auto", "z-down", build=True).endswith("decompose it alone with --up z")
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(5000, 3))
    assert upside_down_doubt(ball, "z") is None
    wall = np.zeros((10, 3))
    wall[:, 1] = np.arange(10)  # after a Y turn every point lies at z = 0; the file's Z spread 9
    assert up_guess_flat(wall, "auto", "y-down").endswith("as written they spread 9 along Z")
    assert up_guess_flat(wall, "z", "y-down") is None


def test_library_build_notes_and_keeps_the_turn(tmp_path, coffee):
    from arboretum_server.batch.tasks import NOTES_KEY, decompose_scan
    from arboretum_server.decompose.examples import UP_AXIS_KEY, file_sha256

    down = tmp_path / "coffee_down.xyz"
    write_points(down, turn_from_zup(coffee[1], "z-down"))
    out = decompose_scan(str(down), file_sha256(down), {"points": 3000, "n_main": 3, "n_lobes": 6})
    assert out.error == "" and len(out.examples) == 3
    note = upside_down_note("auto", "z-down", build=True)
    assert out.notes[0] == note
    params = out.examples[0].provenance.parameters
    assert params[UP_AXIS_KEY] == "z-down" and params[NOTES_KEY][0] == note
    bare = tmp_path / "coffee_bare_down.xyz"
    write_points(bare, turn_from_zup(coffee[0], "z-down"))
    out = decompose_scan(str(bare), file_sha256(bare), {"points": 3000, "n_main": 3, "n_lobes": 6})
    assert out.error.endswith("if the file is upside down, decompose it alone with --up z-down")
