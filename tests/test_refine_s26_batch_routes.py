"""The pieces of a split are routed again in one batch (session 26, helper-184).

``secondary.make_lobes`` routes again every new lobe whose shared branch and its unsmoothed path both cross a
foreign lobe (a split into 20 of the leaf-on pine's bench lobes: all 20 pieces). Since session 26 the first
reroute of a call also routes every later lobe that would be routed again then (``secondary._batch_routes``):
one ``merge_secondaries``, centring and smoothing call for all of them instead of one per lobe. Each step works
path by path (KD-tree and grid queries point by point, shape contexts and smoothing polyline by polyline), so
a batch gives the same arrays as single calls, and the split the same lobes as routing each piece alone.

The cases (session 30): the tests named lobes 5 and 21, splits that reroute all 20 pieces. With the lobes of our
own k-means (session 30) the bench's strokes no longer split lobe 5 in 20, so each case is now found by a rule
(``_rerouting_all``): the first lobe from 5 (from 21) on that the bench's strokes split in 20 with all 20 pieces
routed again, each piece routed alone (``_batch_routes`` off, so the rule does not lean on the batch the tests
check). On today's lobes the rule gives lobes 7 and 21 (lobe 6 reroutes 14 of its 20 pieces)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

PIECES = 20
"""How many pieces each split makes (the bench's splits in 20)."""


@pytest.fixture(scope="module")
def leaf_on_pine():
    from split_helpers import leaf_on_pine

    return leaf_on_pine()


def _split(d, lobe: int):
    from arboretum_server.decompose.refine import split_lobe
    from split_helpers import bench_strokes

    return split_lobe(d, lobe, bench_strokes(d, lobe, PIECES))


@cache
def _rerouting_all(first: int) -> int:
    """The first lobe ``j >= first`` of the leaf-on pine that the bench's strokes split in 20 with every piece
    routed again, counted with each piece routed alone (``_batch_routes`` off): the test's case, found on the
    lobes of the day (lobe 5, the case before session 30, no longer splits in 20)."""
    from arboretum_server.decompose import secondary as s
    from arboretum_server.decompose.refine import split_lobe
    from split_helpers import bench_strokes, leaf_on_pine

    d, routed, single = leaf_on_pine(), [0], s._routes

    def counted(r, centres, js, targets):
        routed[0] += len(js)
        return single(r, centres, js, targets)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(s, "_routes", counted)
        m.setattr(s, "_batch_routes", lambda lobes, r, js, targets: None)
        for j in range(first, len(d.lobes)):
            try:
                strokes = bench_strokes(d, j, PIECES)
            except AssertionError:  # the bench's strokes do not split lobe j in 20
                continue
            routed[0] = 0
            split_lobe(d, j, strokes)
            if routed[0] == PIECES:
                return j
    raise AssertionError(f"no lobe from {first} on splits in {PIECES} with every piece routed again")


def _same_lobes(a, b) -> bool:
    return len(a.lobes) == len(b.lobes) and all(
        np.array_equal(x.members, y.members) and np.array_equal(x.centre, y.centre)
        and np.array_equal(x.hull_vertices, y.hull_vertices) and np.array_equal(x.hull_faces, y.hull_faces)
        and np.array_equal(x.segment, y.segment) and (x.parent, x.parent_vertex) == (y.parent, y.parent_vertex)
        for x, y in zip(a.lobes, b.lobes))


@pytest.mark.parametrize("first", [5, 21])
def test_batched_reroutes_give_the_lobes_of_one_reroute_at_a_time(leaf_on_pine, monkeypatch, first):
    from arboretum_server.decompose import secondary as s

    lobe = _rerouting_all(first)  # today 7 and 21

    used, batched = [0], [0]
    single = s._routes

    def counted(r, centres, js, targets):
        (batched if len(js) > 1 else used)[0] += len(js)
        return single(r, centres, js, targets)

    monkeypatch.setattr(s, "_routes", counted)
    fast = _split(leaf_on_pine, lobe)
    assert batched[0] == PIECES and used[0] == 0  # every piece routed again, all from the one batch
    monkeypatch.setattr(s, "_batch_routes", lambda lobes, r, js, targets: None)  # each piece routed alone
    batched[0] = used[0] = 0
    alone = _split(leaf_on_pine, lobe)
    assert batched[0] == 0 and used[0] == PIECES
    assert _same_lobes(fast, alone)


def test_a_batch_of_routes_equals_each_route_alone(leaf_on_pine, monkeypatch):
    from arboretum_server.decompose import secondary as s

    seen = []

    def keep(lobes, r, js, targets):
        seen.append((r, [lobes[j].centre.copy() for j in js], list(js), list(targets)))
        return batch(lobes, r, js, targets)

    batch = s._batch_routes
    monkeypatch.setattr(s, "_batch_routes", keep)
    _split(leaf_on_pine, _rerouting_all(5))  # today lobe 7 (lobe 5 before session 30)
    r, centres, js, targets = seen[0]
    assert len(js) == PIECES  # one batch of all 20 pieces
    together = s._routes(r, centres, js, targets)
    for k, (c, j, t) in enumerate(zip(centres, js, targets)):
        one = s._routes(r, [c], [j], [t])[0]
        assert one[0] == together[k][0] and one[4:] == together[k][4:]
        for a, b in zip(one[1:4], together[k][1:4]):
            assert np.array_equal(a, b)
