"""``--up auto`` on scans with ground and on rows of trees (session 18). A Z-up tree standing on a ground
disc as wide as it is tall was guessed Y up at 0.91-0.99 and turned on its side (41 of 144 synthetic
files read wrong, every one with ground), and trees in a row far apart were guessed Y at 0.97 and
decomposed lying down as one tree (helper-126's hunt). Ground under an axis is now left out before that
axis is scored, and counts for it; a row's footprint, a line, is no longer taken for a slab on edge."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.cli import main
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import AUTO_Y_CONFIDENCE, read_points, write_points
from arboretum_library.pointio_spatial import ground_band, guess_up_axis


@pytest.fixture(scope="module")
def tree(scans_dir):
    """Scan 06 (tree7), Z up, its own units."""
    return read_points(scans_dir / "06_adtree_tree7" / "06_adtree_tree7.xyz").points


def _on_ground(tree, radius: float, slope: float, n: int = 20_000) -> tuple[np.ndarray, int]:
    """``tree`` on a ground disc ``radius`` x its height wide, rising ``slope`` along X: (points, n)."""
    rng = np.random.default_rng(3)
    h = float(np.ptp(tree[:, 2]))
    a, r = rng.uniform(0, 2 * np.pi, n), radius * h * np.sqrt(rng.uniform(0, 1, n))
    c = np.median(tree[:, :2], axis=0)
    x, y = r * np.cos(a), r * np.sin(a)
    ground = np.c_[c[0] + x, c[1] + y, tree[:, 2].min() + slope * x + rng.normal(0, 0.002 * h, n)]
    return np.vstack([tree, ground]), n


@pytest.mark.parametrize("radius, slope", [(1.0, 0.0), (2.0, 0.0), (4.0, 0.0), (2.0, 0.15)])
def test_a_tree_on_wide_ground_stands_on_z(tree, radius, slope):
    pts, _ = _on_ground(tree, radius, slope)
    axis, sure = guess_up_axis(pts)
    assert axis == "z" and sure > 0.95, (axis, sure)  # before: ('y', 0.91-0.99)
    axis, sure = guess_up_axis(zup_to_yup(pts))
    assert axis == "y" and sure > 0.95, (axis, sure)


def test_the_ground_band_is_the_ground(tree):
    pts, n = _on_ground(tree, 2.0, 0.15)
    band = ground_band(pts, 2)
    is_ground = np.r_[np.zeros(len(tree), bool), np.ones(n, bool)]
    assert band[is_ground].mean() > 0.99  # nearly all of the ground
    assert band[~is_ground].mean() < 0.03  # the trunk's foot at most
    assert ground_band(pts, 1) is None  # seen from the side, the ground is a wall, not ground
    assert ground_band(tree, 2) is None  # scan 06 was cropped at its foot


@pytest.mark.parametrize("apart, count", [(1000.0, 2), (50.0, 2), (15.0, 5)])
def test_trees_in_a_row_are_not_turned(tree, tmp_path, apart, count):
    row = np.vstack([tree + [apart * k, 0.0, 0.0] for k in range(count)])
    axis, sure = guess_up_axis(row)
    assert axis == "z" or sure < AUTO_Y_CONFIDENCE, (axis, sure)  # before: ('y', 0.97)
    write_points(tmp_path / "row.npy", row)
    assert read_points(tmp_path / "row.npy").up_axis == "z"
    axis, sure = guess_up_axis(zup_to_yup(row))  # and a Y-up row is turned
    assert axis == "y" and sure >= AUTO_Y_CONFIDENCE, (axis, sure)


def test_decompose_refuses_a_row_as_several_trees(tree, tmp_path, capsys):
    """Before: read as Y up and decomposed lying down, exit 0."""
    path = tmp_path / "row.npy"
    write_points(path, np.vstack([tree + [15.0 * k, 0.0, 0.0] for k in range(5)]))
    assert main(["decompose", str(path)]) == 2
    assert "5 separate trunks found 60 apart at the base" in capsys.readouterr().err
