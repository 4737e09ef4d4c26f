"""Growth far from the world origin (UTM, geocentric): the same tree, translated, grows the same twigs.

The HBL's coordinates are rounded to multiples of 2^-20 m so that adding the UTM offset is exact in
float64: the far tree is then exactly the near one moved, and any difference is the grower's.
"""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.grow.attraction import default_step
from arboretum_server.grow.demo import demo_hbl, icosphere
from arboretum_server.grow.hulls import mesh_volume
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.tree import grow_tree

UTM = np.array([500000.0, 5400000.0, 0.0])
QUANTUM = 2.0**-20


def _quantized(hbl):
    """``hbl`` with every coordinate on the 2^-20 m grid (so + UTM is exact)."""
    return hbl.map_positions(lambda a: np.round(a / QUANTUM) * QUANTUM)


def translated(hbl, offset):
    return hbl.map_positions(lambda a: a + offset)


@pytest.fixture(scope="module")
def near_and_far():
    near = _quantized(demo_hbl(np.random.default_rng(11), n_lobes=5))
    far = translated(near, UTM)
    assert np.array_equal(far.lobes[0].hull_vertices - UTM, near.lobes[0].hull_vertices)  # exact shift
    grow = lambda h: grow_tree(h, GrowOptions(), np.random.default_rng(0))  # noqa: E731
    return grow(near), grow(far)


def test_far_tree_grows_the_same_twigs(near_and_far):
    near, far = near_and_far
    assert near.twig_count > 1000
    assert far.twig_count == near.twig_count
    assert far.step == pytest.approx(near.step, rel=1e-12)
    assert len(far.positions) == len(near.positions)
    np.testing.assert_array_equal(far.parents, near.parents)
    np.testing.assert_allclose(far.positions - UTM, near.positions, rtol=0, atol=1e-6)
    np.testing.assert_allclose(far.radii, near.radii, rtol=1e-9)


def test_far_tree_grows_the_same_leaves(near_and_far):
    near, far = near_and_far
    assert len(near.leaves.sizes) > 200
    assert len(far.leaves.sizes) == len(near.leaves.sizes)
    np.testing.assert_allclose(far.leaves.centres - UTM, near.leaves.centres, rtol=0, atol=1e-6)
    np.testing.assert_allclose(far.leaves.sizes, near.leaves.sizes, rtol=1e-9)


def test_default_step_is_translation_invariant(near_and_far):
    hbl = _quantized(demo_hbl(np.random.default_rng(11), n_lobes=5))
    d0 = default_step(hbl.lobes)
    for off in ([1e4, 0, 0], UTM, [4e6, 4e6, 3e6]):
        assert default_step(translated(hbl, np.array(off, float)).lobes) == pytest.approx(d0, rel=1e-7)


def test_growth_origin_is_the_root_in_whole_metres():
    from arboretum_server.grow.tree import growth_origin

    hbl = demo_hbl(np.random.default_rng(11), n_lobes=2)
    assert np.array_equal(growth_origin(hbl), np.zeros(3))  # near trees grow where they stand
    moved = translated(hbl, np.array([500000.3, 5400000.7, 12.2]))
    assert np.array_equal(growth_origin(moved), np.round(moved.root))


@pytest.mark.parametrize("offset", [[1e4, 0, 0], [5e5, 5.4e6, 0], [4e6, 4e6, 3e6]])
def test_mesh_volume_is_translation_invariant(offset):
    v, f = icosphere(3)
    v = v * 0.3
    near = mesh_volume(v, f)
    assert near == pytest.approx(4 / 3 * np.pi * 0.3**3, rel=0.02)
    assert mesh_volume(v + np.array(offset), f) == pytest.approx(near, rel=1e-7)
