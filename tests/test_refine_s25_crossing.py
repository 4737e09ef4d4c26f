"""Every piece of a split reaches its centre clear (session 25, helper-176).

Session 23's probe (134 splits of 5 trees into 20-100 pieces) left 2 splits with a piece whose branch ran
2.8-3.5 cm deep (0.8 m scale) through a kept lobe: the leaf-on pine's lobes 6 and 22 split in 20. Every
route along the split lobe's branch (``tunnel.along``) reached that piece through a sibling piece of 6-14
points (too few for a closed carved shape) or a kept lobe, and so did the bends through its own points; the
piece lay open on its far side. Now ``tunnel._along_free`` bends the branch through a waypoint in the open
2.5-10 cm round the piece's centre."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def leaf_on_pine():
    from split_helpers import leaf_on_pine

    return leaf_on_pine()


def _strokes(d, j: int, k: int) -> list[np.ndarray]:
    from split_helpers import bench_strokes

    return bench_strokes(d, j, k)


@pytest.mark.parametrize("lobe", [6, 22])
def test_a_split_in_20_whose_piece_crossed_now_has_none(leaf_on_pine, lobe):
    # Before: one piece each crossing kept lobe 10 (3.45 cm deep) and 11 (2.8 cm deep).
    from arboretum_server.decompose.clear import foreign
    from arboretum_server.decompose.evaluate import crossings
    from arboretum_server.decompose.refine import split_lobe

    d = leaf_on_pine
    out = split_lobe(d, lobe, _strokes(d, lobe, 20))
    assert crossings(out.hbl) == 0
    lobes = list(out.lobes)
    assert not [j for j, lb in enumerate(lobes) if foreign(lobes, j, lb.segment, out.options.step / 2)]
    n_kept = len(d.lobes) - 1
    pieces = lobes[n_kept:]
    assert len(pieces) == 20 and len(out.hbl.lobes) == len(d.lobes) + 19
    assert np.array_equal(np.sort(np.concatenate([p.members for p in pieces])), np.sort(d.lobes[lobe].members))
    for k, lb in enumerate(lobes[:n_kept]):  # the kept lobes keep their hulls
        assert lb.hull_vertices is d.lobes[k + (k >= lobe)].hull_vertices
    for p in pieces:
        assert np.allclose(p.segment[-1], p.centre)
        assert np.allclose(p.segment[0], out.mains.segments[p.parent][p.parent_vertex])


def test_only_the_piece_no_other_repair_clears_takes_the_free_bend(leaf_on_pine, monkeypatch):
    # One piece of the split of lobe 6 reaches _along_free; without it that piece crosses, as before.
    from arboretum_server.decompose import tunnel
    from arboretum_server.decompose.evaluate import crossings
    from arboretum_server.decompose.refine import split_lobe

    d, real, calls = leaf_on_pine, tunnel._along_free, []

    def spy(lobes, j, seg, tol, box, step=0.005):
        route = real(lobes, j, seg, tol, box, step)
        calls.append((j, route))
        return route

    monkeypatch.setattr(tunnel, "_along_free", spy)
    out = split_lobe(d, 6, _strokes(d, 6, 20))
    assert len(calls) == 1 and calls[0][1] is not None
    j, route = calls[0]
    piece = out.lobes[j]
    assert piece.segment is route and np.allclose(route[-1], piece.centre)
    assert np.allclose(route[0], d.lobes[6].segment[0])  # it leaves along the split lobe's branch
    monkeypatch.setattr(tunnel, "_along_free", lambda *a, **k: None)
    assert crossings(split_lobe(d, 6, _strokes(d, 6, 20)).hbl) == 1


def test_sphere_directions_are_unit_and_spread():
    from arboretum_server.decompose.tunnel import _sphere

    s = _sphere(32)
    assert s.shape == (32, 3)
    assert np.allclose(np.linalg.norm(s, axis=1), 1.0)
    assert np.allclose(s.mean(axis=0), 0.0, atol=0.05)
    dots = s @ s.T - 2 * np.eye(32)
    assert dots.max() < 0.9  # no two within 25 degrees
