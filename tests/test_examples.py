"""The VRTree section 4 experiment scripts (examples/0*.py), each run as a user runs it: a subprocess with
a temporary --out; the tests read the JSON it prints and check its figures and pictures."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run(script: str, out: Path, seed: int = 0) -> dict:
    """Run ``examples/script`` headless; its JSON summary (fails with its stderr when it fails)."""
    env = {**os.environ, "OMP_WAIT_POLICY": "PASSIVE"}
    env.pop("DISPLAY", None)
    done = subprocess.run([sys.executable, str(EXAMPLES / script), "--out", str(out), "--seed", str(seed)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def picture(out: Path, name: str) -> np.ndarray:
    """The picture as an (H, W, 3) array; it must not be a blank image."""
    img = np.asarray(Image.open(out / name).convert("RGB"))
    assert img.reshape(-1, 3).std(axis=0).max() > 10, f"{name} is blank"
    return img


def test_freestyle_makes_four_grown_trees_of_distinct_shapes(tmp_path):
    s = run("01_freestyle.py", tmp_path)
    trees = s["trees"]
    assert set(trees) == {"pine", "walnut", "eucalyptus", "mixed"}
    for name, t in trees.items():
        assert t["examples"] >= 6, name
        assert t["merges"] >= 1, name  # joined to the trunk by recombination
        assert t["lobes"] >= 40 and t["leaves"] > 500 and t["nodes"] > t["leaves"], name
        assert 0.6 < t["height"] < 1.2, name  # the libraries' 0.8 m scale
    # the species' outlines survive decomposition and re-assembly: the conifer and the eucalyptus are
    # slender, the walnut broad
    assert trees["pine"]["height_width"] > trees["walnut"]["height_width"] + 0.3
    assert trees["eucalyptus"]["height_width"] > trees["walnut"]["height_width"] + 0.3
    assert picture(tmp_path, "freestyle_grown.png").shape == (480, 4 * 320 + 3 * 2, 3)
    picture(tmp_path, "freestyle_hbl.png")


@pytest.fixture(scope="module")
def editing(tmp_path_factory) -> tuple[dict, Path]:
    """``02_tree_editing.py`` at seed 0, run once: (its summary, its --out folder). The editing test reads it,
    the repeatability test compares a second run with it (it made two runs of its own, at seed 3)."""
    out = tmp_path_factory.mktemp("editing")
    return run("02_tree_editing.py", out, seed=0), out


def test_tree_editing_keeps_the_untouched_examples_bit_identical(editing):
    s, out = editing
    # loaded whole at identity, the assembly is the decomposition's HBL again, bit for bit
    assert s["whole_equals_original"] is True
    assert s["whole_branches_identical"] == s["original_branches"] > 40
    assert s["whole_lobes_identical"] == s["original_lobes"] > 40
    # one example replaced, two added; everything else unchanged
    assert s["edited_placements"] == s["examples"] + 2
    assert s["removed_branches"] >= 1 and s["removed_branches_left"] == 0
    assert s["untouched_branches"] == s["original_branches"] - s["removed_branches"]
    assert s["untouched_branches_identical"] == s["untouched_branches"]
    assert s["edited_merges"] == 3  # each new example joined by Algorithm 1
    assert s["new_branches"] >= 3 and s["edited_branches"] == s["untouched_branches"] + s["new_branches"]
    picture(out, "editing.png")


def test_tree_editing_is_repeatable(tmp_path, editing):
    a = dict(editing[0])
    b = run("02_tree_editing.py", tmp_path / "b", seed=0)
    a.pop("seconds"), b.pop("seconds")
    assert a == b


def test_incomplete_scan_filling_raises_coverage_of_the_complete_scan(tmp_path):
    s = run("04_incomplete_scan.py", tmp_path)
    c = s["coverage"]
    # the 90 degree wedge (azimuth 0-90) is found from the incomplete scan alone
    assert 0 <= s["gap_start_deg"] <= 20 and 60 <= s["gap_width_deg"] <= 100
    assert s["copies"] >= 3 and s["lobes"]["filled"] > s["lobes"]["skeleton_only"]
    assert s["d"] == pytest.approx(0.02 * s["height"], abs=1e-3)
    assert c["filled_d0.02"] > c["skeleton_only_d0.02"]
    assert c["filled_gap_d0.02"] > c["skeleton_only_gap_d0.02"] + 0.1
    assert c["filled_gap_d0.05"] > c["skeleton_only_gap_d0.05"] + 0.3
    for name in ("skeleton_only", "filled"):  # coverage grows with d
        assert c[f"{name}_d0.01"] <= c[f"{name}_d0.02"] <= c[f"{name}_d0.05"]
    picture(tmp_path, "incomplete.png")


@pytest.mark.slow
def test_image_guided_placement_matches_the_reference_silhouette(tmp_path):
    s = run("03_image_guided.py", tmp_path)
    assert s["placed"] >= 5
    assert s["iou"] >= 0.5  # 0.72 measured with seed 0; 0.57-0.58 with seeds 1 and 2
    assert s["iou"] > s["iou_random_placement"] + 0.08 > s["iou_trunk_only"] + 0.08
    steps = s["iou_cells_per_step"]
    assert all(b > a for a, b in zip(steps, steps[1:]))  # every greedy step raised the overlap
    assert picture(tmp_path, "image_guided.png").shape == (256, 3 * 256 + 2 * 2, 3)
