"""``--up auto`` on a low, wide crown with a short, sparsely scanned trunk (session 25, helper-179).

``_upright_score`` measures the trunk as the width of the lowest tenth of the extent counted from its
0.5 percentile. The guiding default tree's trunk is 12 % of its height but holds 0.75 % of its points
(224 of 40,000; 0.56 % once the ground band took its foot), so the 0.5 percentile lay at the crown's base
and the "trunk" slice was crown, 1.05 times the crown's width: Z scored -0.16 + the ground bonus against
0.45 for Y (the ground disc seen edge on), and on flat ground every Y-up file read Z (Y at 0.686-0.687,
under ``AUTO_Y_CONFIDENCE``). Measured from the lowest point (``_hidden_trunk``), the slice is the trunk
(0.04 of the crown's width) and the tree reads the way it is written at 0.997."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio_up import _upright_score, auto_up, guess_up
from arboretum_library.truth import load_truth
from arboretum_server.decompose.toytree import toy_scan

ASSETS = Path(__file__).resolve().parents[1] / "assets" / "synth"


def _zdown(pts: np.ndarray) -> np.ndarray:
    return pts * np.array([1.0, -1.0, -1.0])


WAYS = {"z": lambda p: p, "y": zup_to_yup, "z-down": _zdown, "y-down": lambda p: zup_to_yup(_zdown(p))}


def _flat(pts: np.ndarray, n: int = 40_000) -> np.ndarray:
    """``pts`` (Z up) on a flat ground disc 1.5 heights round its lowest point."""
    rng = np.random.default_rng(0)
    h, foot = float(np.ptp(pts[:, 2])), pts[np.argmin(pts[:, 2])]
    r, a = 1.5 * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    ground = np.stack([r * np.cos(a), r * np.sin(a), rng.normal(0, 0.002 * h, n)], axis=1)
    return np.concatenate([pts, ground + foot])


@pytest.fixture(scope="module")
def guiding() -> np.ndarray:
    """The guiding default tree (a crown as wide as it is tall from 12 % of its height), 40,000 points:
    the shipped truth, equal to ``report.grow_truth("guiding", "default", 1)`` (no growth in the test)."""
    truth = load_truth(ASSETS / "guiding_default_s1_truth.npz")
    h = float(np.ptp(truth.positions[:, 2]))
    return toy_scan(truth, n=40000, noise=0.002 * h, seed=1)[0]


def _blob(trunk_points: int, trunk_top: float = 0.12, seed: int = 0) -> np.ndarray:
    """A dome-shaped crown 1.2 times as wide as it is tall (20,000 points in a half ellipsoid, flat side
    down at ``trunk_top`` of the height: branches spreading level at the crown's base) over a trunk 0.03
    of the height wide holding ``trunk_points`` points (Z up)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(20_000, 3))
    u *= (rng.uniform(0, 1, 20_000) ** (1 / 3) / np.linalg.norm(u, axis=1))[:, None]
    u[:, 2] = np.abs(u[:, 2])
    crown = u * np.array([0.6, 0.6, 1.0 - trunk_top]) + np.array([0.0, 0.0, trunk_top])
    a = rng.uniform(0, 2 * np.pi, trunk_points)
    trunk = np.stack([0.015 * np.cos(a), 0.015 * np.sin(a), rng.uniform(0, trunk_top + 0.02, trunk_points)], axis=1)
    return 10.0 * np.concatenate([crown, trunk])


def test_the_guiding_default_tree_on_flat_ground_reads_the_way_written(guiding):
    """4 ways on flat ground: each read as written at 0.997 (before: 0.686-0.689, both Y files read Z)."""
    cloud = _flat(guiding)
    for way, turn in WAYS.items():
        guess = guess_up(turn(cloud))
        assert (guess.direction, auto_up(guess)) == (way, way) and guess.confidence > 0.99, (way, guess)


def test_the_guiding_default_trees_trunk_is_its_foot(guiding):
    """Z up, no ground: its upright score along Z is 2.38 (before -0.09: the foot slice was crown), and
    along Y (on its side) unchanged at 0.20."""
    assert _upright_score(guiding, 2, None) == pytest.approx(2.38, abs=0.01)
    assert _upright_score(guiding, 1, None) == pytest.approx(0.199, abs=0.001)


def test_a_sparse_trunk_under_a_wide_crown_is_read():
    """A dome 1.2 times as wide as tall over a trunk of 12 % of the height holding 200 of 20,200 points
    (1 %): Z scores 2.39 (before -0.27, the foot slice in the crown); on flat ground each way reads as
    written at 0.997 (before 0.62, both Y files read Z)."""
    blob = _blob(200)
    assert _upright_score(blob, 2, None) == pytest.approx(2.385, abs=0.01)
    cloud = _flat(blob)
    for way, turn in WAYS.items():
        guess = guess_up(turn(cloud))
        assert (guess.direction, auto_up(guess)) == (way, way) and guess.confidence > 0.99, (way, guess)


def test_a_crown_without_a_trunk_keeps_its_score():
    """No trunk under the dome: its foot is the crown's as before (-0.21), and on flat ground it stays
    unsure (0.65): a tree as wide as it is tall with no trunk seen is told by its ground alone."""
    blob = _blob(0, trunk_top=0.0)
    assert _upright_score(blob, 2, None) == pytest.approx(-0.214, abs=0.01)
    assert guess_up(zup_to_yup(_flat(blob))).confidence == pytest.approx(0.65, abs=0.01)
