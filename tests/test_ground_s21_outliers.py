"""Ground and trunk base (session 21, helper-143): many uniform outliers. With 10-20 % of them strewn in a
box round scan 10 (a pine on a ground patch 2.5 m wide), the outliers held each other 3 deep down to the
box's floor, ``held`` found nothing strewn below its points and the ground was missed: the floor was cut
instead and the root went 4-24 % of the height under the ground (9-20 of 20 draws, exit 0). The held
search now asks for 6, 12, then 24 points held (``GROUND_HELD_MORE``), and counts only held points below
a ground (the outliers under it were 1.3-2.7 % of the points, over ``GROUND_BELOW``), but only when 3 %
of the points or more stand scattered: helper-146's review found the deeper searches cutting a dense
branch layer as the ground of a tree with none. A trunk base refused among many scattered points names
them after its own words."""


import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_server.decompose.ground import find_ground
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.preprocess import prepare
from arboretum_server.decompose.strays import scattered
from factories import layered_tree, prepared_root, real_scan, strewn


def _pine():
    """A tree 20 tall (a trunk 0.15 wide, a cone of crown from 4 up) on a ground patch 2.5 wide at z = 0:
    3,000 ground points first, then 20,000 of the tree."""
    rng = np.random.default_rng(100)
    a, z = rng.uniform(0, 2 * np.pi, 5000), rng.uniform(0, 20, 5000)
    trunk = np.c_[0.15 * np.cos(a), 0.15 * np.sin(a), z]
    zc = rng.uniform(4, 20, 15000)
    r, b = 1.2 * (20 - zc) / 16 * np.sqrt(rng.uniform(0, 1, len(zc))), rng.uniform(0, 2 * np.pi, len(zc))
    ground = np.c_[rng.uniform(-1.25, 1.25, (3000, 2)), rng.normal(0, 0.02, 3000)]
    return np.r_[ground, trunk, np.c_[r * np.cos(b), r * np.sin(b), zc]]


@pytest.mark.parametrize("share, seed", [(0.1, 0), (0.1, 1), (0.15, 0), (0.2, 0)])
def test_outliers_holding_each_other_leave_a_small_ground_found(share, seed):
    # before: no ground, or the outliers' floor 3.8-4.0 under the ground (the tree 20 tall); now the
    # ground within 0.1 of z = 0, all 3,000 of its points cut and under 0.5 % of the tree's
    pts = _pine()
    ground, surface = find_ground(np.r_[pts, strewn(pts, share, seed)], 0.015)
    assert surface is not None and abs(surface.height(np.zeros((1, 2)))[0]) < 0.11
    assert ground[:3000].all() and ground[3000:len(pts)].sum() < 0.005 * (len(pts) - 3000)


@pytest.mark.parametrize("share, seed", [(0.1, 1), (0.12, 2), (0.15, 2), (0.2, 0)])
def test_many_outliers_leave_scan_10_rooted_on_its_ground(share, seed):
    # scan 10 with 10-20 % uniform outliers: root 19.6-24.6 % of the height under the clean scan's in
    # these draws (the 15 % one with no ground cut at all); now within 0.6 % of it, the ground cut
    pts, clean = real_scan("10")
    noise = strewn(pts, share, seed)
    o = DecomposeOptions()
    prepared = prepare(np.r_[pts, noise], o, np.random.default_rng(o.seed))
    assert prepared.ground_removed >= 2800 + 0.1 * len(noise)  # the clean scan's 2,821 and the outliers under it
    assert np.linalg.norm(prepared.root_scan - clean) < 0.01 * np.ptp(pts[:, 2])


def test_a_base_refused_among_scattered_points_names_them():
    # scan 06 (no ground) with 20 % uniform outliers, this draw: "no trunk base found (...); crop the scan
    # to one standing tree" before, which sent the user after the wrong cause
    pts, _ = real_scan("06")
    with pytest.raises(InputError, match=r"^point cloud: no trunk base found .*; 1[0-9]% of the points stand "
                       r"scattered apart .*outlier filter"):
        prepared_root(np.r_[pts, strewn(pts, 0.2, 2)])


def test_scattered_counts_outliers_not_a_sparse_ground():
    # uniform outliers: about their share; a sparse ground round the tree (its points as far apart as
    # outliers') and a clean tree: 0, so their refusals keep their own words
    pts = _pine()[3000:]
    noise = strewn(pts, 0.1, 0)
    assert 0.05 < scattered(np.r_[pts, noise]) < 0.1  # some lie in the crown
    xy = np.random.default_rng(0).uniform(-8, 8, (2000, 2))
    assert scattered(np.r_[pts, np.c_[xy, np.zeros(2000)]]) == 0.0
    assert scattered(pts) == 0.0


@pytest.mark.parametrize("seed, trunk_points, slope", [(0, 1000, 0.0), (0, 2000, 0.0), (1, 1000, 0.2), (2, 1000, 0.4)])
def test_a_branch_layer_over_a_sparse_trunk_is_no_ground(seed, trunk_points, slope):
    # helper-146's review: the 6-24 deep held searches found a layer as ground (3.9-12.9 up a 20 tall
    # tree, 3,000-13,000 points cut) in 24 of 48 such clouds; they run only among many scattered points
    pts = layered_tree(seed, trunk_points, slope)
    ground, surface = find_ground(pts, DecomposeOptions().ground_band)
    assert surface is None and ground.sum() == 0
    assert scattered(pts) < 0.03


def test_two_trees_among_outliers_are_still_called_two_trees():
    # helper-146's review: with 5-15 % outliers the scattered points' line replaced "separate trunks"
    pine = _pine()
    two = np.r_[pine, pine * [1, 1, 0.9] + [3.0, 0.0, 0.0]]
    with pytest.raises(InputError, match=r"separate trunks found .*; [0-9]+% of the points stand scattered apart"):
        prepared_root(np.r_[two, strewn(two, 0.05, 4)])


@pytest.mark.parametrize("share, wider, seed", [(0.3, 0.05, 1), (0.3, 0.1, 0), (0.4, 0.2, 0)])
def test_the_gate_reads_heavy_outliers_as_the_whole_cloud_does(share, wider, seed):
    # helper-147's review: read on 5,000 points alone, scan 10's share of scattered points fell under 3 %
    # with 30-40 % outliers (thinned, they are each other's neighbours), the gate closed and the root
    # went 2.1-23 % of the height off; their neighbours are now found among all the points
    pts, clean = real_scan("10")
    noise = strewn(pts, share, seed, wider)
    assert scattered(np.r_[pts, noise], 5000) > 0.5 * share
    assert np.linalg.norm(prepared_root(np.r_[pts, noise]) - clean) < 0.015 * np.ptp(pts[:, 2])
