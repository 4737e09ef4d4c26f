"""LAS and LAZ files are Z up by their format (ASPRS: Z is elevation), so ``--up auto`` reads them Z up
without a guess (session 20). Before, a LAS tree beside a long wall, or with returns under its ground,
could be guessed Y up and decomposed lying on its side. ``scan info`` still prints the guess, and says
which option reads the file the guess's way when it is sure. Other formats keep the guess, made once:
``scan_stats`` reuses the one ``read_points`` made."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.commands.scan import format_stats
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import ReadOptions, read_points, scan_stats, write_points
from arboretum_library.pointio_up import guess_up
from factories import las_file as _las


def _tree(seed: int = 1) -> np.ndarray:
    """A toy tree (N, 3), Z up, 7.5 m: a trunk 0.2 m wide to 3 m, a ball-shaped crown 3 m wide above."""
    rng = np.random.default_rng(seed)
    t, a = rng.uniform(0, 3, 1500), rng.uniform(0, 2 * np.pi, 1500)
    trunk = np.stack([0.1 * np.cos(a), 0.1 * np.sin(a), t], axis=1)
    d = rng.normal(size=(6000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.concatenate([trunk, d * 1.5 * rng.uniform(0.6, 1.0, (6000, 1)) + [0, 0, 4.5]])


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_las_is_read_z_up_whatever_its_shape(tmp_path, ext):
    lying = zup_to_yup(_tree())  # the tree written Y up: its shape says Y, surely
    assert guess_up(lying).direction == "y" and guess_up(lying).confidence > 0.95
    cloud = read_points(_las(tmp_path / f"lying{ext}", lying))
    assert cloud.up_axis == "z" and cloud.up_guess is None
    np.testing.assert_allclose(cloud.points, lying, atol=6e-4)  # as stored: millimetre integers
    as_ply = read_points(write_points(tmp_path / "lying.ply", lying))
    assert as_ply.up_axis == "y" and as_ply.up_guess is not None
    np.testing.assert_allclose(as_ply.points[:, 2], lying[:, 1], atol=1e-9)


def test_las_given_y_is_turned(tmp_path):
    lying = zup_to_yup(_tree())
    cloud = read_points(_las(tmp_path / "lying.las", lying), ReadOptions(up="y"))
    assert cloud.up_axis == "y"
    np.testing.assert_allclose(cloud.points[:, 2], lying[:, 1], atol=6e-4)


def test_scan_info_names_the_option_for_a_las_whose_shape_disagrees(tmp_path):
    lying = read_points(_las(tmp_path / "lying.las", zup_to_yup(_tree())))
    s = scan_stats(lying)
    assert (s["up_axis"], s["up_guess"]) == ("z", "y") and s["up_confidence"] > 0.95
    line = next(x for x in format_stats(s).splitlines() if "up axis" in x)
    assert "LAS is Z up by its format" in line and line.endswith("pass --up y if the file is not")
    assert "LAS" not in format_stats(s, up_asked="z")  # the user said Z: no advice
    upright = scan_stats(read_points(_las(tmp_path / "upright.las", _tree())))
    assert (upright["up_axis"], upright["up_guess"]) == ("z", "z")
    assert "LAS" not in format_stats(upright)
    ply = scan_stats(read_points(write_points(tmp_path / "lying.ply", zup_to_yup(_tree()))))
    assert ply["up_axis"] == "y" and "LAS" not in format_stats(ply)


def test_scan_stats_reuses_the_guess_read_points_made(tmp_path, monkeypatch):
    import arboretum_library.pointio_stats as stats

    cloud = read_points(write_points(tmp_path / "tree.ply", _tree()))
    monkeypatch.setattr(stats, "guess_up", lambda pts: pytest.fail("guessed a second time"))
    s = scan_stats(cloud)
    assert (s["up_guess"], s["up_confidence"]) == (cloud.up_guess.direction, round(cloud.up_guess.confidence, 3))
    given = read_points(tmp_path / "tree.ply", ReadOptions(up="z"))
    assert given.up_guess is None
    monkeypatch.undo()
    assert scan_stats(given)["up_guess"] == "z"


def test_an_upside_down_las_on_its_ground_names_z_down(tmp_path):
    tree = _tree()
    rng = np.random.default_rng(3)
    r, a = 8.0 * np.sqrt(rng.uniform(0, 1, 8000)), rng.uniform(0, 2 * np.pi, 8000)
    ground = np.c_[r * np.cos(a), r * np.sin(a), rng.normal(0, 0.01, 8000)]
    down = np.r_[tree, ground] * [1, -1, -1]
    cloud = read_points(_las(tmp_path / "down.las", down, scale=0.001))
    assert cloud.up_axis == "z"
    s = scan_stats(cloud)
    assert (s["up_guess"], s["up_by_shape"]) == ("z-down", "z-down")
    assert "LAS is Z up by its format, so the guess was not applied: pass --up z-down" in format_stats(s)
