"""Radii: the pipe model by hand, HBL branch radii kept whatever the twig density, never a thicker child."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_library.model import HBL
from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.radii import depths, lobe_twig_radii, pipe_radii, tip_heights
from arboretum_server.grow.skeleton import branch_graph
from arboretum_server.grow.tree import grow_tree, hbl_radii_consistent
from factories import make_hbl

#        0
#        1
#      2   5
#     3 4   6
PARENTS = np.array([-1, 0, 1, 2, 2, 1, 5])


def test_pipe_model_by_hand():
    tips = np.array([0, 0, 0, 1.0, 2.0, 0, 3.0])
    r = pipe_radii(PARENTS, tips, 2.0)
    assert r[3] == 1.0 and r[4] == 2.0 and r[6] == 3.0
    assert r[2] == pytest.approx(np.sqrt(5.0))
    assert r[5] == pytest.approx(3.0)
    assert r[1] == pytest.approx(np.sqrt(14.0)) and r[0] == pytest.approx(r[1])
    r25 = pipe_radii(PARENTS, tips, 2.5)
    assert r25[1] == pytest.approx((1 + 2**2.5 + 3**2.5) ** (1 / 2.5))


def test_depths_and_tip_heights():
    assert depths(PARENTS).tolist() == [0, 1, 2, 3, 3, 2, 3]
    assert tip_heights(PARENTS).tolist() == [3, 2, 1, 0, 0, 1, 0]


@pytest.mark.parametrize("exponent", [2.0, 2.5])
def test_pipe_mode_no_child_is_thicker_than_its_parent(exponent):
    hbl = make_hbl(np.random.default_rng(3), n_main=3, n_lobes=4)
    t = grow_tree(hbl, GrowOptions(pipe_exponent=exponent, branch_radii="pipe"), np.random.default_rng(0))
    child = np.flatnonzero(t.parents >= 0)
    assert (t.radii[child] <= t.radii[t.parents[child]] * (1 + 1e-12)).all()
    tips = np.setdiff1d(np.arange(len(t.parents)), t.parents)
    twig_tips = tips[t.lobe[tips] >= 0]
    assert np.allclose(t.radii[twig_tips], 0.08 * t.step)
    # the trunk carries every tip: r_root^e = sum of tip radii^e
    assert t.radii[0] ** exponent == pytest.approx((t.radii[tips] ** exponent).sum(), rel=1e-9)


def test_lobe_twig_radii_by_hand():
    """Branch 0-1-2; lobe 0 (nodes 3-5) fits under its bud, lobe 1 (6-11) is scaled down, then floored."""
    parents = np.array([-1, 0, 1, 2, 3, 3, 2, 6, 6, 6, 6, 6])
    lobe = np.array([-1, -1, -1, 0, 0, 0, 1, 1, 1, 1, 1, 1])
    branch = np.array([0.1, 0.05, 0.02])
    r = lobe_twig_radii(parents, lobe, branch, 0.01, 0.0)
    assert r[:3].tolist() == branch.tolist()
    assert r[3] == pytest.approx(0.01 * np.sqrt(2)) and r[4] == r[5] == 0.01  # pipe sum < bud: unscaled
    assert r[6] == pytest.approx(0.02)  # sqrt(5) * 0.01 > 0.02: scaled to the bud's radius
    assert np.allclose(r[7:], 0.02 / np.sqrt(5))
    floored = lobe_twig_radii(parents, lobe, branch, 0.01, 0.0095)
    assert np.allclose(floored[7:], 0.0095) and floored[6] == pytest.approx(0.02)


@pytest.fixture(scope="module")
def by_density():
    hbl = demo_hbl(np.random.default_rng(0), n_lobes=8)
    return hbl, {d: grow_tree(hbl, GrowOptions(density=d), np.random.default_rng(7)) for d in (0.5, 1.0, 2.0)}


def test_density_leaves_branch_radii_unchanged(by_density):
    hbl, trees = by_density
    assert hbl_radii_consistent(hbl)
    graph = branch_graph(hbl)
    n0 = len(graph.radii)
    for t in trees.values():
        np.testing.assert_allclose(t.radii[:n0], graph.radii, rtol=0, atol=1e-12)  # trunk, mains, secondaries
    assert trees[0.5].twig_count < trees[1.0].twig_count < trees[2.0].twig_count
    assert trees[0.5].radii[0] == trees[2.0].radii[0] == pytest.approx(0.18)


@pytest.mark.parametrize("density", [0.5, 1.0, 2.0])
def test_hbl_mode_no_child_is_thicker_than_its_parent(by_density, density):
    t = by_density[1][density]
    child = np.flatnonzero(t.parents >= 0)
    assert (t.radii[child] <= t.radii[t.parents[child]] * (1 + 1e-12)).all()
    twig = np.flatnonzero(t.lobe >= 0)
    roots = twig[t.lobe[t.parents[twig]] < 0]
    bud = np.zeros(t.lobe.max() + 1)
    bud[t.lobe[roots]] = t.radii[t.parents[roots]]
    assert (t.radii[roots] <= bud[t.lobe[roots]]).all()  # a lobe's twigs never outgrow its branch
    floor = np.minimum(0.3 * 0.08 * t.step, bud[t.lobe[twig]])  # min_twig_radius x tip_radius
    assert (t.radii[twig] >= floor * (1 - 1e-12)).all()


def test_auto_falls_back_to_the_pipe_model_without_meaningful_radii():
    hbl = make_hbl(np.random.default_rng(3), n_main=3, n_lobes=4)  # secondaries thicker than their joint
    assert not hbl_radii_consistent(hbl)
    flat = HBL(hbl.root, tuple(dataclasses.replace(b, radii=np.full(len(b.points), 0.01)) for b in hbl.branches),
               hbl.lobes)
    assert not hbl_radii_consistent(flat)
    auto = grow_tree(hbl, GrowOptions(), np.random.default_rng(0))
    pipe = grow_tree(hbl, GrowOptions(branch_radii="pipe"), np.random.default_rng(0))
    forced = grow_tree(hbl, GrowOptions(branch_radii="hbl"), np.random.default_rng(0))
    assert auto.radii.tolist() == pipe.radii.tolist()
    assert forced.radii[0] == hbl.branches[0].radii[0] != pytest.approx(pipe.radii[0])
