"""``--up auto`` on a tree on terraced ground (session 22). A ground column (1/50 of the cloud wide)
across a terrace's edge holds both levels; its band (3 % of the extent above its lowest point) left
the upper level in, a step of 6 % of the height: those 1 % of the points widened the trunk's slice
from 0.37 m to 14-15 m and left the axis unsure (helper-131's scan 06 and apple on terraces: 0.52-0.61;
Z-up files stayed Z up for lack of confidence, Y-up ones were not turned). ``ground_band`` now also
leaves out, in such a column, the points within the band of a neighbouring column's ground a step
above (more than the band, at most ``GROUND_STEP``), where nothing stands on that level."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library import pointio_ground, pointio_up
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import ReadOptions, read_points
from arboretum_library.pointio_up import ground_band, guess_up

Z = ReadOptions(up="z")


@pytest.fixture(scope="module")
def scan06(scans_dir) -> np.ndarray:
    return read_points(scans_dir / "06_adtree_tree7" / "06_adtree_tree7.xyz", Z).points


def _on_terraces(pts: np.ndarray, step: float, n: int = 40_000) -> np.ndarray:
    """``pts`` (Z up, no ground) on a ground disc 1.5 heights round its lowest point, terraced as
    helper-131's: a level every 0.3 heights along X, ``step`` of the height higher each, flat within
    0.15 heights of the trunk (10 edges, 5 up and 5 down)."""
    rng = np.random.default_rng(0)
    h = float(np.ptp(pts[:, 2]))
    r, a = 1.5 * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(a), r * np.sin(a)
    z = step * h * np.floor(x / (0.3 * h)) * (np.abs(x) > 0.15 * h) + rng.normal(0, 0.002 * h, n)
    return np.concatenate([pts, np.stack([x, y, z], axis=1) + pts[np.argmin(pts[:, 2])]])


@pytest.mark.parametrize("step", [0.06, 0.08, 0.1])
def test_a_tree_on_terraces_reads_as_surely_as_on_flat_ground(scan06, step):
    """Z up and Y up, read the way written at 0.995, as on flat ground (0.994). Before: the wrong axis at
    0.535-0.554, so the Z-up files stayed Z up only for lack of confidence and the Y-up ones were not
    turned."""
    cloud = _on_terraces(scan06, step)
    for way, pts in (("z", cloud), ("y", zup_to_yup(cloud))):
        guess = guess_up(pts)
        assert guess.direction == way and guess.confidence > 0.98, (way, guess)


def test_the_upper_level_of_a_column_across_an_edge_is_ground(scan06):
    """The band of scan 06 on terraces 6 % of the height high holds every ground point (before: 98.4 %;
    the rest, the upper levels' strips along the edges, made the trunk's slice) and the tree's points
    in it lie within 3.5 % of its height of its foot (2.5 % on flat ground; the extent is taller)."""
    cloud = _on_terraces(scan06, 0.06)
    band, m = ground_band(cloud, 2), len(scan06)
    assert band[m:].all()
    foot, h = scan06[:, 2].min(), np.ptp(scan06[:, 2])
    assert 100 < band[:m].sum() < 300 and cloud[:m][band[:m], 2].max() - foot < 0.035 * h


def _one_step(pts: np.ndarray, step: float, n: int = 40_000) -> np.ndarray:
    """``pts`` (Z up, no ground) on a ground disc 1.5 heights round its lowest point with one edge,
    ``step`` of the height high, running along Y through the trunk (its mean over the lowest 10 %)."""
    rng = np.random.default_rng(0)
    h, foot = float(np.ptp(pts[:, 2])), pts[np.argmin(pts[:, 2])]
    trunk = pts[pts[:, 2] < foot[2] + 0.1 * h][:, :2].mean(axis=0) - foot[:2]
    r, a = 1.5 * h * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(a), r * np.sin(a)
    z = step * h * (x > trunk[0]) + rng.normal(0, 0.002 * h, n)
    return np.concatenate([pts, np.stack([x, y, z], axis=1) + foot])


@pytest.mark.parametrize("step", [0.06, 0.1])
def test_a_step_through_the_trunk_leaves_its_foot(scan06, step):
    """One edge through scan 06's trunk: Z up at 0.99 (before: 0.61), and the band holds about as much
    of the tree as before (156-161 points): the trunk's columns, where more points stand just above the
    upper level than lie on it, keep it (without that 458 of the tree's points, up to 8.7 % of its
    height, went into the band; the guiding default tree's trunk slice then reached into its crown). A
    step of 10 % of the tree's height is more than 10 % of the extent (0.95 of the height):
    ``GROUND_STEP`` is 0.15."""
    cloud = _one_step(scan06, step)
    guess = guess_up(cloud)
    assert guess.direction == "z" and guess.confidence > 0.98, guess
    band, m = ground_band(cloud, 2), len(scan06)
    assert band[m:].mean() > 0.998 and band[:m].sum() < 200


def _grid_steps(cloud: np.ndarray) -> tuple:
    """``_steps`` of ``cloud`` (Z up) as ``ground_band`` finds them along +Z, and the extent."""
    pts = pointio_up._sample(cloud)
    h = pts[:, 2]
    lo, hi = np.percentile(h, [0.5, 99.5])
    height = float(hi - lo)
    cell = pointio_ground._largest_extent(pts) / pointio_ground.GROUND_CELLS
    column, shape = pointio_ground._columns(pts[:, :2], cell)
    found, low, surface = pointio_ground._ground_surface(h, column, shape, cell, height)
    assert found
    base = np.where(np.isfinite(surface) & ~(np.abs(low - surface) < 0.1 * height), surface, low)
    return pointio_ground._steps(low, surface, base, height), height


@pytest.mark.parametrize("slope", [0.0, 0.15, 0.3, 0.45])
def test_flat_and_sloped_ground_have_no_steps(scan06, slope):
    """A guard: ground without steps has no terrace edge, so its band is exactly as before (``_steps`` is
    new; before it, scan 06's band on these four grounds was the same, point for point). Without
    ``STEP_COLUMNS`` the trunk's column on a 15-45 % slope found 1-4 rises and lost 118-428 of its points
    to the band."""
    cloud = _on_terraces(scan06, 0.0)
    cloud[len(scan06):, 2] += slope * (cloud[len(scan06):, 0] - cloud[len(scan06):, 0].mean())
    assert _grid_steps(cloud)[0] == ()


def test_terraces_rise_by_their_step(scan06):
    """On terraces 6 % of the height high, the edges' columns rise by one step (0.06 of the tree's
    height, within 0.01), in lines across the ground, never more than ``GROUND_STEP``."""
    (lowest, highest), height = _grid_steps(_on_terraces(scan06, 0.06))
    rise = highest[highest > 0]
    assert len(rise) >= 100 and rise.max() <= pointio_ground.GROUND_STEP * height
    assert np.median(rise) / np.ptp(scan06[:, 2]) == pytest.approx(0.06, abs=0.01)
    assert np.all(lowest <= highest)
