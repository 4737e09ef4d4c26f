"""``arboretum decompose`` on a scan written upside down (session 19): ``--up auto`` turns it the right way
up and says so in a note; the result is the upright scan's; ``--up z-down`` says the same by hand."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.pointio import ReadOptions, read_points, write_points
from arboretum_library.pointio_up import turn_from_zup
from arboretum_server.decompose.notes import up_guess_flat, upside_down_note

COFFEE = sample_scans()[0]


def _run(capsys, *argv: str) -> dict:
    assert main(["decompose", *map(str, argv), "--json", "--points", "3000", "--main", "3", "--lobes", "6"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def coffee():
    return read_points(COFFEE, ReadOptions(up="z")).points


@pytest.mark.parametrize("way", ["z-down", "y-down"])
def test_an_upside_down_scan_decomposes_as_the_upright_one(tmp_path, capsys, coffee, way):
    down = tmp_path / f"coffee_{way}.xyz"
    write_points(down, turn_from_zup(coffee, way))
    upright = _run(capsys, COFFEE, "--up", "z")
    turned = _run(capsys, down)
    assert turned["notes"][0] == (f"--up auto found the file upside down (its trunk at the top) and turned it "
                                  f"the right way up (--up {way}); pass --up {way[0]} to read it as written")
    assert not any("upside down" in n for n in upright["notes"])
    for key in ("main_branches", "lobes", "height"):
        assert turned["stats"][key] == pytest.approx(upright["stats"][key], rel=1e-6), key
    by_hand = _run(capsys, down, "--up", way)
    assert not any("upside down" in n for n in by_hand["notes"])  # the user said so: nothing to tell
    assert by_hand["stats"]["height"] == pytest.approx(upright["stats"]["height"], rel=1e-6)


def test_the_way_up_notes():
    assert upside_down_note("auto", "z") is None
    assert upside_down_note("z-down", "z-down") is None
    assert upside_down_note("auto", "y-down").endswith("(--up y-down); pass --up y to read it as written")
    wall = np.zeros((10, 3))
    wall[:, 1] = np.arange(10)  # after a Y turn every point lies at z = 0; the file's Z spread 9
    assert up_guess_flat(wall, "auto", "y-down").endswith("as written they spread 9 along Z")
    assert up_guess_flat(wall, "z", "y-down") is None


def test_library_build_notes_and_keeps_the_turn(tmp_path, coffee):
    from arboretum_server.batch.tasks import NOTES_KEY, decompose_scan
    from arboretum_server.decompose.examples import UP_AXIS_KEY, file_sha256

    down = tmp_path / "coffee_down.xyz"
    write_points(down, turn_from_zup(coffee, "z-down"))
    out = decompose_scan(str(down), file_sha256(down), {"points": 3000, "n_main": 3, "n_lobes": 6})
    assert out.error == "" and len(out.examples) == 3
    note = upside_down_note("auto", "z-down")
    assert out.notes[0] == note
    params = out.examples[0].provenance.parameters
    assert params[UP_AXIS_KEY] == "z-down" and params[NOTES_KEY][0] == note
