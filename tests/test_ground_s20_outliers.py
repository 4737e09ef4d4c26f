"""Ground and trunk base (session 20, helper-141): uniform outliers under a tree. Without ground, lone
outliers under the trunk were the lowest points of its base band, which then held no big cluster, and
the root went onto them (scan 07 with 1 % of them: 12-20 % of the height too low, exit 0) or the band
spread too wide ("no trunk base": scan 01 and the harmonic apple with 1.5-3 %). On scan 10 (a pine on
a small ground) 5 % of them held columns under the ground in ``held``'s sampling, the ground was
missed and the root went 14-24 % of the height under it in 8 of 10 draws. And ``find_ground``'s last
resort, the outliers' sparse floor, is the first search's, not searched for a second time."""


import numpy as np
import pytest

import arboretum_server.decompose.ground_surface as ground_surface
from arboretum_server.decompose.ground import find_ground
from arboretum_server.decompose.trunkbase import find_root
from factories import prepared_root, real_scan, strewn


def test_lone_points_under_a_column_are_not_its_base():
    # a trunk 2,000 points strong and three lone points 15 % of the height under it: the band from the
    # lowest held 3 of them, its 10 lowest 7 trunk points, no big cluster, and the root went 15 % low
    rng = np.random.default_rng(0)
    a, z = rng.uniform(0, 2 * np.pi, 2000), rng.uniform(0, 1, 2000)
    trunk = np.c_[0.02 * np.cos(a), 0.02 * np.sin(a), z]
    lone = np.array([[0.1, 0.0, -0.15], [-0.1, 0.05, -0.15], [0.0, -0.1, -0.15]])
    root = find_root(np.r_[trunk, lone])
    assert abs(root[2] - z.min()) < 0.01
    assert np.linalg.norm(root[:2]) < 0.03


@pytest.mark.parametrize("key, share, seed", [("07", 0.01, 0), ("07", 0.01, 1), ("07", 0.015, 2), ("07", 0.02, 1),
                                              ("01", 0.015, 0), ("01", 0.03, 0)])
def test_outliers_under_a_tree_with_no_ground_leave_its_root(key, share, seed):
    # scan 07 (buttress roots) and scan 01 (a coffee tree), no ground: 12-22 % of the height too low,
    # or "no trunk base" (scan 01 with 1.5 % and more), before; 0.01-0.24 % now
    pts, clean = real_scan(key)
    h = float(np.ptp(pts[:, 2]))
    root = prepared_root(np.r_[pts, strewn(pts, share, seed)])
    assert np.linalg.norm(root - clean) < 0.01 * h


@pytest.mark.parametrize("seed", [0, 2, 3, 9])
def test_five_percent_outliers_leave_a_small_ground_found(seed):
    # scan 10 and 5 % uniform outliers: the ground missed (or only the outliers' floor cut) and the root
    # 14-24 % of the height under it in these draws; now cut, the root within 0.1 % of the clean scan's
    pts, clean = real_scan("10")
    noise = strewn(pts, 0.05, seed)
    ground, surface = find_ground(np.r_[pts, noise], 0.015)
    assert surface is not None and ground[:len(pts)].sum() >= 2400  # 2,569 without the noise
    root = prepared_root(np.r_[pts, noise])
    assert np.linalg.norm(root - clean) < 0.01 * np.ptp(pts[:, 2])


def test_the_last_resort_reuses_the_first_search(monkeypatch):
    # scan 07 with 2 % outliers takes the outliers' sparse floor: the first search's surfaces are fitted
    # once (plane: first search and held pass; before, a third time for the last resort)
    pts, _ = real_scan("07")
    calls = []
    plane = ground_surface.ground_plane
    monkeypatch.setattr(ground_surface, "ground_plane", lambda *a: calls.append(1) or plane(*a))
    ground, surface = find_ground(np.r_[pts, strewn(pts, 0.02, 0)], 0.015)
    assert surface is not None and ground[:len(pts)].sum() == 0
    assert len(calls) == 2


def test_a_sparse_trunk_is_a_column_not_lone_points():
    # 600 points of the toy tree: its trunk's foot has no 4 neighbours within 2 % of the height either,
    # and the band started 20 % of the height up the trunk until the points under it had to stand apart
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts = toy_scan(toy_truth(), leaf_fraction=0.5, seed=1)[0]
    sparse = pts[np.random.default_rng(600).choice(len(pts), 600, replace=False)]
    h = np.ptp(sparse[:, 2])
    root = find_root(sparse)
    assert root[2] - sparse[:, 2].min() < 0.02 * h
    assert np.linalg.norm(root[:2]) < 0.05 * h
