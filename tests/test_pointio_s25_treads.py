"""``--up auto`` on a tree at the top of a flight of 8 % steps going down, the ground 3 heights out
(session 25, helper-177).

A ground column is then 0.12 heights wide and, with 40,000 ground points, holds about 10 of them: two or
three treads. ``_treads`` leaves a column's own treads under its neighbour's level out with the ground
when they hold 5 points or more; a sparse column's middle tread and the level over it held 4, stayed out
of the band and widened the trunk's slice (the harmonic apple: Z 0.45 against Y 0.41 written Z up, 0.52
sure). They now go at 3 points (``TREAD_HELD``)."""

from __future__ import annotations

import numpy as np

from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio_up import auto_up, ground_band, guess_up
from arboretum_server.decompose.report import grow_truth
from arboretum_server.decompose.toytree import toy_scan


def _apple() -> np.ndarray:
    """The harmonic apple (seed 1), a toy scan of 40,000 points, Z up, no ground."""
    truth = grow_truth("harmonic", "apple", 1)
    h = float(np.ptp(truth.positions[:, 2]))
    return toy_scan(truth, n=40000, noise=0.002 * h, seed=1)[0]


def _at_the_top_of_a_flight(pts: np.ndarray, n: int = 40_000) -> np.ndarray:
    """``pts`` on a ground disc 3 heights round its foot with 8 steps of 8 % of the height going down along
    +X from 0.1 heights, treads 6 % deep (the lower level beyond)."""
    rng = np.random.default_rng(0)
    h, foot = float(np.ptp(pts[:, 2])), pts[np.argmin(pts[:, 2])]
    r, a = 3.0 * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(a), r * np.sin(a)
    steps = np.where(x > 0.1 * h, np.minimum(np.floor((x - 0.1 * h) / (0.06 * h)) + 1, 8), 0)
    ground = np.stack([x, y, -0.08 * h * steps + rng.normal(0, 0.002 * h, n)], axis=1)
    return np.concatenate([pts, ground + foot])


def test_an_apple_at_the_top_of_a_flight_going_down_reads_z_written_z_up():
    """Written Z up and Y down (its mirror): read as written at 0.96 (before: Z and Y-down at 0.52, which
    --up auto kept on Z: the Y-down file read wrong)."""
    cloud = _at_the_top_of_a_flight(_apple())
    y_down = zup_to_yup(cloud * np.array([1.0, -1.0, -1.0]))
    for way, pts in (("z", cloud), ("y-down", y_down)):
        guess = guess_up(pts)
        assert auto_up(guess) == way and guess.confidence > 0.95, (way, guess)


def test_the_band_holds_the_sparse_columns_treads():
    """20,000 ground points (a column holds about 5), written Z up: 47 of them are left out of the band
    (75 before), and the band holds the same 63 of the tree's points as before."""
    tree = _apple()
    band = ground_band(_at_the_top_of_a_flight(tree, 20_000), 2)
    assert (~band[len(tree):]).sum() <= 50 and band[:len(tree)].sum() == 63
