"""Pipe-model radii: exact on a hand-made tree, never thicker children on a grown one."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.radii import depths, pipe_radii, tip_heights
from arboretum_server.grow.tree import grow_tree
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
def test_no_child_is_thicker_than_its_parent(exponent):
    hbl = make_hbl(np.random.default_rng(3), n_main=3, n_lobes=4)
    t = grow_tree(hbl, GrowOptions(pipe_exponent=exponent), np.random.default_rng(0))
    child = np.flatnonzero(t.parents >= 0)
    assert (t.radii[child] <= t.radii[t.parents[child]] * (1 + 1e-12)).all()
    tips = np.setdiff1d(np.arange(len(t.parents)), t.parents)
    twig_tips = tips[t.lobe[tips] >= 0]
    assert np.allclose(t.radii[twig_tips], 0.08 * t.step)
    # the trunk carries every tip: r_root^e = sum of tip radii^e
    assert t.radii[0] ** exponent == pytest.approx((t.radii[tips] ** exponent).sum(), rel=1e-9)
