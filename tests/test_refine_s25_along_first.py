"""A piece of a split lobe takes the split lobe's own branch before the bent and carved repairs (session 25,
helper-180).

``secondary._reroute`` gives a piece whose rerouted branch crosses another lobe the straight repair, then, when
that crosses too, a branch along the split lobe's own (``tunnel.along``), which stayed clear; before, the bent
repair, ``carve.unwrap``, ``tunnel.behind`` and ``moved_centre`` came first and ``along`` only after all of them
(``refine._along_split``). On the leaf-on pine's bench splits in 20 of lobes 5 and 21, the bent and carved repairs
gave pieces branches bent by 102 and 162 degrees at their sharpest; along the split lobe's branch the sharpest
bends are 56 and 45 degrees, and lobe 5's pieces' branches are 266 -> 230 cm long in all (0.8 m frame)."""

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


def _pieces(d, lobe: int):
    from arboretum_server.decompose.refine import split_lobe

    out = split_lobe(d, lobe, _strokes(d, lobe, 20))
    return out, list(out.lobes[len(d.lobes) - 1:])


def _sharpest(seg: np.ndarray) -> float:
    from arboretum_server.decompose.evaluate import turning_angles

    return float(np.degrees(turning_angles(seg)).max()) if len(seg) > 2 else 0.0


@pytest.mark.parametrize("lobe, sharpest", [(5, 56.0), (21, 45.0)])
def test_split_pieces_bend_less_along_the_split_lobes_branch(leaf_on_pine, lobe, sharpest):
    # Before: sharpest bends 102 (lobe 5) and 162 degrees (lobe 21).
    from arboretum_server.decompose.evaluate import crossings

    out, pieces = _pieces(leaf_on_pine, lobe)
    assert crossings(out.hbl) == 0
    assert len(pieces) == 20
    assert max(_sharpest(np.asarray(p.segment)) for p in pieces) == pytest.approx(sharpest, abs=1.0)


def test_split_pieces_branches_are_shorter_and_start_on_the_split_lobes_branch(leaf_on_pine):
    # Before: 266.0 cm of branches in all, 5 of 20 starting where the split lobe's branch starts.
    d = leaf_on_pine
    split = d.lobes[5]
    _, pieces = _pieces(d, 5)
    total = 100 * sum(float(np.linalg.norm(np.diff(p.segment, axis=0), axis=1).sum()) for p in pieces)
    assert total == pytest.approx(230.1, abs=1.0)
    on_branch = [p for p in pieces if p.parent == split.parent and p.parent_vertex == split.parent_vertex
                 and np.allclose(p.segment[0], split.segment[0])]
    assert len(on_branch) == 13

