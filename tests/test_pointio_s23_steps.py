"""``--up auto`` on a flight of steps (session 23, helper-160).

A flight of steps whose treads are one ``ground_band`` column wide (6 % of the tree's height; the cloud is
3 heights wide, a column 1/50 of it) puts two treads in each column, with the neighbour on one side a
step higher and on the other a step lower: no column had a level neighbour opposite, so ``_steps`` found
no edge and the upper tread stayed out of the band (the foot slice 2.9 heights wide, Z at 0.54-0.72). The
ground, two levels 0.4 heights apart joined by the flight, is no plane either, so ``_planar`` kept an
upside-down file as written, and its Y-down twin read Y up at 0.81-0.97."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio_up import ground_band, guess_up
from factories import real_scan


def _zdown(pts: np.ndarray) -> np.ndarray:
    return pts * np.array([1.0, -1.0, -1.0])


WAYS = {"z": lambda p: p, "y": zup_to_yup, "z-down": _zdown, "y-down": lambda p: zup_to_yup(_zdown(p))}


def _on_stairs(pts: np.ndarray, rise: float, n: int = 40_000) -> np.ndarray:
    """``pts`` (Z up, no ground) on a ground disc 1.5 heights round its foot, with a flight of 8 steps of
    ``rise`` of the height, treads 6 % of it deep, starting 0.1 heights from the foot along +X (no
    risers: helper-154's stairs)."""
    rng = np.random.default_rng(0)
    h, foot = float(np.ptp(pts[:, 2])), pts[np.argmin(pts[:, 2])]
    r, a = 1.5 * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(a), r * np.sin(a)
    steps = np.where(x > 0.1 * h, np.minimum(np.floor((x - 0.1 * h) / (0.06 * h)) + 1, 8), 0)
    z = steps * rise * h + rng.normal(0, 0.002 * h, n)
    return np.concatenate([pts, np.stack([x, y, z], axis=1) + foot])


@pytest.mark.parametrize("key", ["06", "10"])
def test_a_tree_by_a_flight_of_steps_reads_the_way_written(key):
    """Steps of 5 % of the height: all 4 ways read as written at 0.995-0.997. Before, scan 06's Z file
    read Y at 0.65 (turned on its side if Y was asked of --up) and its Y file Z; both scans' Z-down files
    read Z up (0.82, 0.94) and their Y-down files Y up (0.82, 0.93): turned upside down."""
    cloud = _on_stairs(real_scan(key)[0], 0.05)
    for way, turn in WAYS.items():
        guess = guess_up(turn(cloud))
        assert guess.direction == way and guess.confidence > 0.95, (key, way, guess)


def test_lower_steps_keep_their_reading():
    """Steps of 3 % of the height (a band's rise) were read right before; they still are, at 0.994."""
    cloud = _on_stairs(real_scan("06")[0], 0.03)
    for way, turn in WAYS.items():
        guess = guess_up(turn(cloud))
        assert guess.direction == way and guess.confidence > 0.95, (way, guess)


def test_the_band_over_a_flight_of_steps_holds_the_upper_treads():
    """Steps of 5 %: 2 of the 40,000 ground points are left out of the band (2,310 before, the upper
    treads), and the tree keeps its foot: the same 129 of its points in the band, none above 2.5 % of its
    height. Steps of 3 % (a band's rise) keep their band point for point."""
    pts = real_scan("06")[0]
    m, h = len(pts), float(np.ptp(pts[:, 2]))
    cloud = _on_stairs(pts, 0.05)
    band = ground_band(cloud, 2)
    assert (~band[m:]).sum() <= 5 and band[:m].sum() == 129
    assert cloud[:m][band[:m], 2].max() - pts[:, 2].min() < 0.026 * h
    low = _on_stairs(pts, 0.03)
    band = ground_band(low, 2)
    assert band[m:].all() and band[:m].sum() == 284

