"""``arboretum library build`` (session 12): species from whole words of the file name, notes on bare
examples and an implausible --height, a wall laid flat by the up guess named, SIGTERM handled as Ctrl-C."""

from __future__ import annotations

import json
import os
import shutil
import signal
import time

import numpy as np
import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_library.store import Library
from arboretum_server.batch.build import BuildOptions, build_library, species_for
from arboretum_server.batch.tasks import NOTES_KEY, SCAN_EXAMPLES_KEY, decompose_scan
from arboretum_server.decompose.examples import file_sha256
from factories import build_then_signal

PINE = sample_scans()[3]
BARE = "1 of 6 examples have no lobes: they grow no twigs or leaves"


@pytest.mark.parametrize(("name", "species"), [
    ("oak_at_pinewood_02.xyz", "oak"), ("Pinecrest_Park_oak_03.laz", "oak"), ("pineapple_field_tree.xyz", "unknown"),
    ("maple_birchwood_rd_01.las", "unknown"), ("soaked_maple_05.xyz", "unknown"), ("red_oak_12.laz", "oak"),
    ("/data/Cherry_tree_07.ply", "cherry"), ("cherries-2.ply", "cherry"), ("BIRCHES.xyz", "birch"),
    ("apples_2.ply", "apple"), ("pine_pine.xyz", "pine"), ("cherry_hill_walnut_2.ply", "unknown"),
    ("/pine/x.xyz", "unknown"),  # the file name only, not its folders
    ("OakTree_01.ply", "oak"), ("AppleTree3.laz", "apple"), ("PineScan.xyz", "pine"),  # CamelCase (the review)
    ("PINE_01.xyz", "pine"), ("WalnutPineMix.xyz", "unknown"),
])
def test_species_from_whole_words_of_the_file_name(name, species):
    assert species_for(name, None) == species
    assert species_for(name, "Ginkgo") == "ginkgo"


def test_several_species_named_give_unknown_and_a_note(tmp_path, capsys):
    lib = tmp_path / "L"
    assert main(["decompose", str(PINE), "--species", "pine", "--library", str(lib)]) == 0
    both = tmp_path / "pine_and_oak_01.xyz"
    shutil.copy(PINE, both)  # the same bytes: a duplicate of a scan already there, so no cluster starts
    result = build_library([str(PINE), str(both)], lib, BuildOptions(species=None))
    skipped, dup = result.records
    assert (skipped.status, skipped.species, dup.status, dup.species) == ("skipped", "pine", "duplicate", "unknown")
    assert dup.notes == ["its file name names 2 species (pine, oak): none guessed, so 'unknown' (N_m = 8, "
                         "N_l = 40); rename the file, or build it alone with --species"]


def test_a_bare_example_is_noted_when_made():
    out = decompose_scan(str(PINE), file_sha256(PINE), {"species": "pine"})
    assert out.error == "" and len(out.examples) == 6
    assert sum(not e.structure.lobes for e in out.examples) == 1
    assert list(out.notes) == [BARE]
    assert out.examples[0].provenance.parameters[NOTES_KEY] == []  # not stored: those examples may be deleted


def test_a_wall_laid_flat_by_the_up_guess_fails_with_its_reason(tmp_path):
    rng = np.random.default_rng(0)
    wall = tmp_path / "wall.xyz"
    np.savetxt(wall, np.c_[rng.uniform(0, 2, 5000), np.zeros(5000), rng.uniform(0, 3, 5000)], fmt="%.4f")
    out = decompose_scan(str(wall), file_sha256(wall), {})
    assert out.error.startswith("--up auto guessed the file is Y up and turned it, which lays all its points at "
                                "one height; as written they spread 3 along Z")
    assert out.error.endswith("arboretum decompose SCAN --up z --library LIB") and not out.examples


def test_an_implausible_height_is_noted_once_for_the_build(tmp_path, capsys):
    lib = tmp_path / "L"
    assert main(["decompose", str(PINE), "--library", str(lib)]) == 0
    capsys.readouterr()
    note = "--height 1e+06 m is taller than any tree (trees are 0.05-150 m tall): the examples are stored at that size"
    result = build_library([str(PINE)], lib, BuildOptions(height=1e6))  # skipped: no cluster
    assert len(result.notes) == 1 and result.notes[0].startswith(note)
    assert build_library([str(PINE)], lib, BuildOptions(height=0.8)).notes == []
    assert main(["library", "build", str(PINE), "--library", str(lib), "--height", "1e6", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["notes"] == result.notes and not any("1e+06" in n for n in data["records"][0]["notes"])
    assert main(["library", "build", str(PINE), "--library", str(lib), "--height", "1e-9"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].startswith("  note: --height 1e-09 m is smaller than a seedling")
    assert "- note: --height 1e-09 m is smaller than a seedling" in (tmp_path / "L-report" / "report.md").read_text()


def test_sigterm_raises_terminated_once_and_waits_for_the_cluster_start():
    from arboretum_server.batch.signals import Terminated, sigterm_stops, sigterm_waits

    before = signal.getsignal(signal.SIGTERM)
    with sigterm_stops():
        with pytest.raises(Terminated):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)
        os.kill(os.getpid(), signal.SIGTERM)  # a second one, while shutting down: ignored
        time.sleep(0.1)
    assert signal.getsignal(signal.SIGTERM) is before
    with sigterm_stops():
        with pytest.raises(Terminated), sigterm_waits():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.1)
            started = True  # not cut short: raised when the block ends
        assert started


@pytest.mark.slow
def test_sigterm_stops_the_build_with_one_line(tmp_path):
    code, text, lib, scans = build_then_signal(tmp_path, 10, 1500, lambda p: p.send_signal(signal.SIGTERM))  # a service manager
    assert code == 143 and "Traceback" not in text and "leaked semaphore" not in text
    assert text.strip().endswith("arboretum library: interrupted (SIGTERM)")
    with Library.open(lib, readonly=True) as L:  # what was stored is whole: every scan all or none
        ids = [L.find_source(file_sha256(p)) for p in scans]
        whole = [not i or len(i) == L.provenance(i[0]).parameters[SCAN_EXAMPLES_KEY] for i in ids]
    assert 1 <= sum(map(bool, ids)) < len(scans) and all(whole)


def test_a_float32_scan_at_utm_is_named_and_the_note_is_kept(tmp_path):
    """The file's precision is its own: said when built and stored with the notes a rerun repeats."""
    from arboretum_library.pointio import read_points

    pts = read_points(sample_scans()[0]).points
    body = np.asarray(pts - pts.min(axis=0) + (5e5, 5.4e6, 300.0), dtype="<f4")
    scan = tmp_path / "utm.ply"
    scan.write_bytes((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(body)}\nproperty float x\n"
                      "property float y\nproperty float z\nend_header\n").encode() + body.tobytes())
    out = decompose_scan(str(scan), file_sha256(scan), {"points": 3000})
    assert "are only 0.5 m apart" in out.notes[0]
    assert out.examples[0].provenance.parameters[NOTES_KEY][0] == out.notes[0]


def test_a_build_after_decompose_runs_with_other_options_sees_no_surplus(tmp_path, capsys):
    """helper-99: decompose stores the same file with other options beside (8 examples, then 3 with
    --main 3); a build counted all 11 against the 8 one run gives and said a --rebuild had stopped
    half-way, advice that would delete the --main 3 set."""
    lib = tmp_path / "L"
    for extra in ([], ["--main", "3"]):
        assert main(["decompose", str(PINE), "--library", str(lib), "--points", "3000", *extra]) == 0
    capsys.readouterr()
    assert main(["library", "build", str(PINE), "--library", str(lib), "--points", "3000", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)["records"][0]
    assert record["status"] == "skipped" and not any("not the" in n for n in record["notes"])


def test_a_y_up_file_built_then_decomposed_is_stored_once(tmp_path, capsys):
    """helper-99: a file that --up auto reads Y up, built and then decomposed with the same options, was
    stored twice: build kept no up axis and a missing one read as Z up. Build keeps it now, and a missing
    one (examples stored before session 12) matches either axis."""
    from arboretum_library.pointio import read_points

    pts = read_points(PINE).points
    scan = tmp_path / "piney.xyz"
    np.savetxt(scan, pts[:, [0, 2, 1]] * [1, 1, -1], fmt="%.4f")  # Y up, right-handed
    lib = tmp_path / "L"
    assert main(["library", "build", str(scan), "--library", str(lib), "--points", "3000", "--species", "pine"]) == 0
    with Library.open(lib, readonly=True) as L:
        assert {L.provenance(i).parameters["up_axis"] for i in L.ids()} == {"y"}
    capsys.readouterr()
    assert main(["decompose", str(scan), "--library", str(lib), "--points", "3000", "--species", "pine", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["stored"] == [] and len(data["already"]) == 6
