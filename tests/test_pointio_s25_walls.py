"""``--up auto`` on a tree by a flight of steps running along Y with a long wall facing X, and on terraces
whose levels run along Y (session 25, helper-177).

The mirror of session 24's case (stairs along X, a wall facing Y) read wrong: turned a quarter about the
up axis, Y has no ground, so the search for a wall along an axis without ground ran, and seen along Y the
flat ground below the flight (or a terrace's level) is a thin line low along Y: it passed for a wall and
Z lost its ground bonus. Session 24's search for a wall standing on an axis's ground never ran, since it
asked for ground along both axes. Two rules were missing on this side of the mirror:
- a wall found along an axis without ground is taken only when the other axis's ground is gone without
  it (it was the wall's face), as ``_wall_on_ground`` already asked; else it is that ground seen edge on;
- with no such wall, a wall standing on the ground of the one axis that has some is looked for, as when
  both have ground."""

from __future__ import annotations

import numpy as np

from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio_up import auto_up, guess_up
from factories import real_scan


def _quarter(pts: np.ndarray) -> np.ndarray:
    """A quarter turn about Z: a flight along +X runs along +Y, a wall facing Y faces X."""
    return np.stack([-pts[:, 1], pts[:, 0], pts[:, 2]], axis=1)


def _on_stairs_by_a_wall(pts: np.ndarray, n: int = 40_000) -> np.ndarray:
    """``pts`` (Z up, no ground) on tests/test_pointio_s24_stairs.py's flight of 8 steps along +X with its wall
    3 heights long along X (facing Y)."""
    from test_pointio_s24_stairs import _on_stairs_by_a_wall as stairs

    return stairs(pts, "y", n)


def _on_terraces(pts: np.ndarray, step: float = 0.06, n: int = 40_000) -> np.ndarray:
    """``pts`` on a ground disc 1.5 heights round its foot with levels ``step`` heights apart every 0.3
    heights along X, the trunk's level 0.3 heights wide (tests/test_pointio_s22_terraces.py)."""
    rng = np.random.default_rng(0)
    h, foot = float(np.ptp(pts[:, 2])), pts[np.argmin(pts[:, 2])]
    r, a = 1.5 * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(a), r * np.sin(a)
    level = np.floor(x / (0.3 * h)) * (np.abs(x) > 0.15 * h)
    return np.concatenate([pts, np.stack([x, y, step * h * level + rng.normal(0, 0.002 * h, n)], axis=1) + foot])


def test_stairs_along_y_and_a_wall_facing_x_read_as_written():
    """Scans 06 and 01, the flight along Y, the wall facing X, written Z up and Y up: read as written at
    0.995 or more. Before: 4 of 4 on their side at 0.99 (Z read Y, Y read Z)."""
    for scan in ("06", "01"):
        cloud = _quarter(_on_stairs_by_a_wall(real_scan(scan)[0]))
        for way, turn in (("z", lambda p: p), ("y", zup_to_yup)):
            guess = guess_up(turn(cloud))
            assert auto_up(guess) == way and guess.confidence > 0.995, (scan, way, guess)


def test_a_terrace_level_along_y_is_not_taken_for_a_wall():
    """Scan 06 on terraces 6 % and 10 % high whose levels run along Y, written Z up: Z at 0.99 or more
    (before: 0.96 both; seen along Y a level passed for a wall and Z lost its ground bonus)."""
    for step in (0.06, 0.10):
        guess = guess_up(_quarter(_on_terraces(real_scan("06")[0], step)))
        assert guess.direction == "z" and guess.confidence > 0.99, (step, guess)
