"""Leaf cards: inside their lobes, oriented, seeded, and as dense as asked."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.tree import grow_tree
from test_grow_hulls import winding_number


@pytest.fixture(scope="module")
def grown():
    hbl = demo_hbl(np.random.default_rng(11), n_lobes=5)
    return hbl, grow_tree(hbl, GrowOptions(), np.random.default_rng(0))


def test_at_least_95_percent_of_cards_inside_lobe_hulls(grown):
    hbl, t = grown
    lv = t.leaves
    assert len(lv.sizes) > 200
    inside = np.zeros(len(lv.sizes), bool)
    for i, lb in enumerate(hbl.lobes):
        sel = lv.lobe == i
        inside[sel] = winding_number(lb.hull_vertices, lb.hull_faces, lv.centres[sel]) > 0.5
    assert inside.mean() >= 0.95


def test_cards_are_oriented(grown):
    hbl, t = grown
    lv = t.leaves
    assert np.allclose(np.linalg.norm(lv.normals, axis=1), 1.0)
    assert np.allclose(np.linalg.norm(lv.axes, axis=1), 1.0)
    assert np.abs((lv.normals * lv.axes).sum(1)).max() < 1e-9
    centres = np.array([lb.centre for lb in hbl.lobes])[lv.lobe]
    outward = ((lv.centres - centres) * lv.normals).sum(1)
    assert (outward > 0).mean() > 0.7  # cards face out of their lobe ...
    assert lv.normals[:, 2].mean() > 0.2  # ... and up
    assert np.ptp(lv.normals, axis=0).min() > 0.5  # with jitter, not all alike


def test_stems_sit_on_twig_nodes(grown):
    _, t = grown
    lv = t.leaves
    stems = lv.centres - lv.axes * lv.sizes[:, None] / 2
    from scipy.spatial import cKDTree

    d, _ = cKDTree(t.positions[t.lobe >= 0]).query(stems)
    assert d.max() < 1e-9


def test_leaf_density_scales_the_count():
    hbl = demo_hbl(np.random.default_rng(11), n_lobes=3)
    n = [len(grow_tree(hbl, GrowOptions(leaf_density=x), np.random.default_rng(0)).leaves.sizes)
         for x in (0.0, 1.0, 2.0)]
    assert n[0] == 0
    assert 1.6 < n[2] / n[1] < 2.4
