"""``--leaf-size`` sets the cards' size, never their number: the same cards hang from the same twigs."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.hulls import build_index, inside
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.tree import grow_tree


@pytest.fixture(scope="module")
def hbl():
    return demo_hbl(np.random.default_rng(11), n_lobes=5)


@pytest.fixture(scope="module")
def by_scale(hbl):
    """Leaves grown with no leaf size, then with 1, 4 and 16 times the default size (1.2 D)."""
    default = grow_tree(hbl, GrowOptions(), np.random.default_rng(0))
    out = {None: default.leaves}
    for k in (1, 4, 16):
        size = 1.2 * default.step * k
        out[k] = grow_tree(hbl, GrowOptions(leaf_size=size), np.random.default_rng(0)).leaves
    return default.step, out


def _stems(lv) -> np.ndarray:
    return lv.centres - lv.axes * lv.sizes[:, None] / 2


def test_explicit_default_size_changes_nothing(by_scale):
    _, lv = by_scale
    assert len(lv[None].sizes) > 200
    for name in ("centres", "normals", "axes", "sizes", "lobe"):
        np.testing.assert_array_equal(getattr(lv[1], name), getattr(lv[None], name))


@pytest.mark.parametrize("k", [4, 16])
def test_bigger_cards_are_the_same_cards(by_scale, k):
    _, lv = by_scale
    big, ref = lv[k], lv[1]
    assert len(big.sizes) == len(ref.sizes)
    np.testing.assert_array_equal(big.lobe, ref.lobe)
    np.testing.assert_allclose(_stems(big), _stems(ref), rtol=0, atol=1e-12)
    np.testing.assert_allclose(big.sizes, ref.sizes * k, rtol=1e-12)
    np.testing.assert_array_equal(big.axes, ref.axes)


def test_default_size_cards_have_their_centres_in_their_lobes(hbl, by_scale):
    _, lv = by_scale
    index = build_index([(lb.hull_vertices, lb.hull_faces) for lb in hbl.lobes])
    assert inside(index, lv[None].centres, lv[None].lobe).all()
    # big cards hang from the same attachments, so their centres may leave the lobe by up to half a card
    assert not inside(index, lv[16].centres, lv[16].lobe).all()
