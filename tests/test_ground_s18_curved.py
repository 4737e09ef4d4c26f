"""Ground removal (session 18, helper-132): curved ground, a shallow ditch, grass 9 % of the height, far
strays above the tree and outliers below the ground. Until session 18 the ground was one plane scaled by
the cloud's full z span: a bowl 2 % of the height deep was kept whole (the trunk crawled over it at
88 degrees), and one point 30 m up moved the root 8 % of the height up the trunk."""

from pathlib import Path

import numpy as np
import pytest

from arboretum_server.decompose.ground import body_span, find_ground
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from factories import ground_disc

N_GROUND = 8000
SCAN_10 = Path(__file__).resolve().parents[1] / "assets" / "scans" / "10_treels_pine" / "10_treels_pine.xyz"


@pytest.fixture
def tree(toy_tree):
    return toy_tree


def _disc(tree, surface, n=N_GROUND, seed=0):
    return ground_disc(tree, surface, n, seed=seed)


def _check(tree, cloud, n_ground=N_GROUND):
    """Decompose ``cloud``: the ground is cut (at most 5 % of the tree's points with it) and the root
    sits on the trunk, within 3 % of the height of its true base."""
    pts, h = tree
    d = decompose(cloud, DecomposeOptions())
    assert n_ground <= d.stats["ground_removed"] <= n_ground + 0.05 * len(pts)
    assert np.linalg.norm(d.root_scan[:2]) < 0.03 * h
    assert abs(d.root_scan[2] - pts[:, 2].min()) < 0.03 * h
    assert 0.95 < d.stats["height"] / h < 1.01
    return d


@pytest.mark.parametrize("k", [0.02, -0.02, 0.04])
def test_bowl_dome_and_valley_are_cut(tree, k):
    # z = k r^2 / H: a bowl (k > 0) 4.5 % of the height deep at the rim, a dome, a valley 9 % deep;
    # before: kept whole (bowl, valley) or refused as "no trunk base" (dome)
    _check(tree, np.r_[tree[0], _disc(tree, lambda x, y: k * (x ** 2 + y ** 2))])


def test_a_shallow_ditch_is_cut(tree):
    # a ditch 1 % of the height deep and 0.2 of it wide, 0.4 of the height from the trunk: more than
    # 1 % of the points lay below the plane, which was refused, and the ground kept whole
    n = 20000
    _check(tree, np.r_[tree[0], _disc(tree, lambda x, y: -0.01 * np.exp(-((x - 0.4) / 0.1) ** 2), n=n)], n)


def test_grass_nine_percent_tall_is_cut(tree):
    # grass as tall as 9 % of the height everywhere on the disc: every slice up to 9 % was grass-wide,
    # so no trunk was found above the ground and the ground was kept whole
    pts, h = tree
    ground = _disc(tree, lambda x, y: 0 * x)
    grass = ground[:6000] + np.c_[np.zeros((6000, 2)), np.random.default_rng(1).uniform(0, 0.09 * h, 6000)]
    d = decompose(np.r_[pts, ground, grass], DecomposeOptions())
    assert d.stats["ground_removed"] >= N_GROUND + 6000
    assert np.linalg.norm(d.root_scan[:2]) < 0.03 * h
    assert d.root_scan[2] - pts[:, 2].min() < 0.11 * h  # on the trunk just above the grass


@pytest.mark.parametrize("above", [1.5, 4.0, 12.0])
def test_a_point_far_above_changes_nothing(tree, above):
    # one point `above` heights over the trunk (a bird): the ground search scaled its cells and band by
    # the full z span, and the cut climbed the trunk (2-8 % of the height) or the cloud was refused
    pts, h = tree
    cloud = np.r_[pts, _disc(tree, lambda x, y: 0 * x)]
    alone = decompose(cloud, DecomposeOptions())
    bird = decompose(np.r_[cloud, [[0.0, 0.0, pts[:, 2].max() + above * h]]], DecomposeOptions())
    assert bird.stats["ground_removed"] == alone.stats["ground_removed"]
    assert bird.root_scan[2] == alone.root_scan[2]  # the downsampling draws differ: x and y move a little
    assert np.linalg.norm(bird.root_scan[:2] - alone.root_scan[:2]) < 0.01 * h


def test_outliers_below_the_ground_go_with_it():
    # scan 10 (a pine on a ground patch 3 m across) and 0.5 % of its points strewn uniformly over a box
    # 20 % wider than the cloud each way: they stretched the z span 1.4 times, the plane was not found,
    # and the root went 4 m below the ground; now the ground is found and those under it go with it
    pine = np.loadtxt(SCAN_10)[:, :3]
    lo, hi = pine.min(axis=0), pine.max(axis=0)
    noise = np.random.default_rng(2).uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (370, 3))
    ground, surface = find_ground(np.r_[pine, noise], 0.015)
    assert surface is not None and ground[:len(pine)].sum() >= 2700  # 2,821 without the noise
    assert ground[len(pine):][noise[:, 2] < pine[:, 2].min()].all()
    clean = decompose(pine, DecomposeOptions()).root_scan
    root = decompose(np.r_[pine, noise], DecomposeOptions()).root_scan
    assert np.linalg.norm(root - clean) < 0.01 * np.ptp(pine[:, 2])


def test_body_span_sets_far_strays_apart():
    z = np.linspace(0.0, 10.0, 5001)
    assert body_span(z) == (0.0, 10.0)  # no stray: the min and the max, exactly
    assert body_span(np.r_[z, 100.0, 101.0]) == (0.0, 10.0)
    assert body_span(np.r_[-50.0, z]) == (0.0, 10.0)
    strewn = np.r_[z, np.linspace(-3.0, 13.0, 20)]  # no gap: at most 1.1 times the 0.1-99.9 % span
    lo, hi = body_span(strewn)
    assert -1.2 < lo < 0 and 10 < hi < 11.2


def test_no_tree_no_ground():
    # a crown's underside is no ground, curved or not: a dome of points with a trunk below it
    rng = np.random.default_rng(3)
    xy = rng.uniform(-3, 3, (6000, 2))
    crown = np.c_[xy, 5.0 - 0.1 * (xy ** 2).sum(axis=1) + rng.uniform(0, 2.0, 6000)]
    trunk = np.c_[rng.normal(0, 0.1, (2000, 2)), rng.uniform(0, 5, 2000)]
    ground, surface = find_ground(np.r_[crown, trunk], 0.015)
    assert not ground.any() and surface is None
