"""``arboretum decompose`` (session 12): notes on bare examples and implausible heights, a scan stored
once (``--rebuild`` to replace it), and a wall turned flat by the up-axis guess named as such."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.store import Library
from arboretum_server.decompose.notes import bare_note, height_notes, up_guess_flat
from factories import float32_ply

COFFEE, PINE = sample_scans()[0], sample_scans()[3]


def _run(capsys, *argv: str) -> dict:
    assert main(["decompose", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _lobes(lib: Path) -> dict[str, int]:
    with Library.open(lib, readonly=True) as L:
        return {e.id: e.descriptors.lobe_count for e in L.entries()}


# ---------------------------------------------------------------- examples without lobes


def test_a_bare_example_gets_a_note_naming_it(tmp_path, capsys):
    lib = tmp_path / "L"
    data = _run(capsys, PINE, "--species", "pine", "--library", lib)
    bare = sorted(i for i, n in _lobes(lib).items() if n == 0)
    assert bare == ["10_treels_pine-0003"] and len(data["stored"]) == 6
    assert data["notes"][-1] == ("1 of 6 examples have no lobes (10_treels_pine-0003): they grow no twigs "
                                 "or leaves")


def test_more_mains_than_lobes_counts_every_bare_example(tmp_path, capsys):
    lib = tmp_path / "L"
    data = _run(capsys, COFFEE, "--main", "40", "--lobes", "5", "--library", lib)
    bare = [i for i, n in _lobes(lib).items() if n == 0]
    assert (len(bare), len(data["stored"])) == (27, 32)
    assert data["notes"][-1].startswith("27 of 32 examples have no lobes (01_rtwig_coffeetree-")
    assert data["notes"][-1].endswith(", ...): they grow no twigs or leaves")


def test_bare_note_wording():
    from types import SimpleNamespace as NS

    ex = [NS(id=f"e{i}", structure=NS(lobes=[] if i in (1, 3) else [0])) for i in range(4)]
    assert bare_note(ex) == "2 of 4 examples have no lobes: they grow no twigs or leaves"  # refine.commit's
    assert bare_note(ex, named=True) == "2 of 4 examples have no lobes (e1, e3): they grow no twigs or leaves"
    assert bare_note(ex[:1]) is None


# ---------------------------------------------------------------- the same scan twice


def test_the_same_scan_with_the_same_options_is_stored_once(tmp_path, capsys):
    lib = tmp_path / "L"
    first = _run(capsys, PINE, "--library", lib)["stored"]
    assert len(first) == 8
    again = _run(capsys, PINE, "--library", lib)
    assert (again["stored"], again["already"], again["examples"]) == ([], first, [])
    assert sorted(_lobes(lib)) == sorted(first)
    assert main(["decompose", str(PINE), "--library", str(lib)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1].startswith(f"already in {lib} as ids {first[0]}, ") and "nothing stored" in out[-1]
    assert "--rebuild" in out[-1] and sorted(_lobes(lib)) == sorted(first)


def test_rebuild_replaces_and_other_options_store_beside(tmp_path, capsys):
    lib = tmp_path / "L"
    first = _run(capsys, PINE, "--library", lib)["stored"]
    redone = _run(capsys, PINE, "--library", lib, "--rebuild")
    assert (len(redone["stored"]), redone["replaced"], redone["already"]) == (8, first, [])
    assert not set(redone["stored"]) & set(first) and sorted(_lobes(lib)) == sorted(redone["stored"])
    pine = _run(capsys, PINE, "--library", lib, "--species", "pine")  # other options: stored beside
    assert len(pine["stored"]) == 6 and len(_lobes(lib)) == 14
    assert pine["notes"][0].startswith("the library also holds 8 examples of this file made with other options")


def test_another_up_axis_is_another_decomposition(tmp_path, capsys):
    """helper-96's review: --up is no decomposition option, so a rerun with --up y matched the --up z
    examples and stored nothing, exit 0, though the pine read Y up has no trunk base at all."""
    lib = tmp_path / "L"
    first = _run(capsys, PINE, "--library", lib, "--up", "z")["stored"]
    assert main(["decompose", str(PINE), "--library", str(lib), "--up", "y"]) == 2  # decomposed: refused
    assert "no trunk base" in capsys.readouterr().err and sorted(_lobes(lib)) == sorted(first)
    again = _run(capsys, PINE, "--library", lib)  # --up auto reads it Z up: the same tree
    assert again["already"] == first and again["stored"] == []


def test_examples_stored_before_session_12_match_either_axis(tmp_path, capsys):
    lib = tmp_path / "L"
    first = _run(capsys, PINE, "--library", lib)["stored"]
    with Library.open(lib) as L:  # as an older decompose stored them: no up axis, no example count
        for i in first:
            e = L.get(i)
            params = {k: v for k, v in e.provenance.parameters.items() if k not in ("up_axis", "scan_examples")}
            L.delete(i)
            L.add(replace(e, provenance=replace(e.provenance, parameters=params)))
    assert _run(capsys, PINE, "--library", lib)["already"] == first


def test_a_rebuild_stopped_half_way_is_named(tmp_path, capsys):
    """--rebuild stores the new examples, then deletes the old ones: stopped in between, the library holds
    both sets, and the next run says so instead of listing 16 as "already there"."""
    lib = tmp_path / "L"
    first = _run(capsys, PINE, "--library", lib)["stored"]
    with Library.open(lib) as L:
        L.add_new([L.get(i) for i in first], "10_treels_pine")  # the new set, the old one not yet deleted
    again = _run(capsys, PINE, "--library", lib)
    assert len(again["already"]) == 16 and again["stored"] == []
    assert again["notes"][-1] == ("the library holds 16 examples of this file made with these options, where one "
                                  "run makes 8 (a --rebuild stopped half-way?); --rebuild replaces them all")
    assert len(_run(capsys, PINE, "--library", lib, "--rebuild")["replaced"]) == 16 and len(_lobes(lib)) == 8


# ---------------------------------------------------------------- --height


@pytest.mark.parametrize(("height", "word"), [(1e-9, "smaller than a seedling"), (1e6, "taller than any tree")])
def test_an_implausible_height_gets_a_note(tmp_path, capsys, height, word):
    data = _run(capsys, PINE, "--height", str(height))
    note = f"--height {height:g} m is {word} (trees are 0.05-150 m tall): the examples are stored at that size"
    assert data["notes"][0].startswith(note)
    assert data["options"]["height"] == height and len(data["examples"]) == 8  # made, as asked


def test_plausible_heights_give_no_height_note():
    assert [height_notes(h) for h in (None, 0.05, 0.8, 150.0)] == [[], [], [], []]
    assert len(height_notes(150.1)) == len(height_notes(0.049)) == 1


# ---------------------------------------------------------------- a wall turned flat by --up auto


def _wall(path: Path) -> Path:
    rng = np.random.default_rng(0)
    np.savetxt(path, np.c_[rng.uniform(0, 2, 5000), np.zeros(5000), rng.uniform(0, 3, 5000)], fmt="%.4f")
    return path


def test_a_wall_laid_flat_by_the_up_guess_says_so(tmp_path, capsys):
    wall = _wall(tmp_path / "wall.xyz")
    assert main(["decompose", str(wall)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"arboretum decompose: error: {wall}: --up auto guessed")
    assert "as written they spread 3 along Z: if Z is up in the file, pass --up z" in err[0]
    assert main(["decompose", str(wall), "--up", "y"]) == 2  # asked for: the plain message is true
    assert "all points lie at one height; this is not a tree" in capsys.readouterr().err


def test_up_guess_flat_only_for_a_guess_that_flattened():
    flat = np.c_[np.arange(10.0), np.arange(10.0), np.zeros(10)]  # as read: one height, file z = -y spreads
    assert up_guess_flat(flat, "auto", "y").endswith("as written they spread 9 along Z")
    assert up_guess_flat(flat, "y", "y") is None and up_guess_flat(flat, "auto", "z") is None
    assert up_guess_flat(np.c_[flat[:, :1], np.zeros((10, 2))], "auto", "y") is None  # flat both ways


# ---------------------------------------------------------------- coordinates too coarse for their size


@pytest.mark.parametrize("offset, noted", [((5e5, 5.4e6, 300.0), True), ((0.0, 0.0, 0.0), False)])
def test_float32_coordinates_at_utm_are_named(tmp_path, capsys, offset, noted):
    """float32 at 5.4e6 m keeps 0.5 m steps: the coffee tree's points snap to that grid (461 graph
    components, 39 of 40 convex lobes in helper-92's run) and the only note blamed repeated points."""
    from arboretum_library.pointio import read_points

    pts = read_points(COFFEE).points
    scan = float32_ply(tmp_path / "t.ply", pts - pts.min(axis=0) + offset)
    data = _run(capsys, scan, "--points", "3000")
    coarse = [n for n in data["notes"] if "float32" in n]
    if noted:
        assert len(coarse) == 1 and "are only 0.5 m apart" in coarse[0] and data["notes"][0] == coarse[0]
    else:
        assert coarse == []
