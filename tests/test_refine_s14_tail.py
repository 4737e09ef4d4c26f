"""The slow tail of "around" inserts (session 14, helper-117): each rerouted secondary branch reweighted the
whole kNN graph again (``weighted`` over every edge). The edges' zones are now gathered once per
``make_lobes`` (``secondary._edge_zones``) and each reroute's graph only rescales its own lobe's edges
(``secondary.foreign_graph``): the same weights bit for bit, so the same routes and lobes."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def leaf_on_pine():
    from split_helpers import leaf_on_pine

    return leaf_on_pine()


def _around(d, j: int) -> np.ndarray:
    """The bench row's "around" selection: lobe ``j``'s extent times 0.35 round its centre."""
    inlobe = np.flatnonzero(d.lobe_of >= 0)
    lb = d.lobes[j]
    extent = float(np.linalg.norm(np.ptp(d.points[lb.members], axis=0)))
    return inlobe[np.linalg.norm(d.points[inlobe] - lb.centre, axis=1) < 0.35 * extent]


def _old_graph(r, j: int):
    """The code before: the whole graph reweighted per reroute."""
    from arboretum_server.decompose import secondary as s

    cost = np.where((r.zone >= 0) & (r.zone != j), s.FOREIGN_COST, np.where(r.zone == j, s.ZONE_COST, 1.0))
    return s.weighted(r.adjacency, cost)


def test_foreign_graph_equals_reweighting(leaf_on_pine):
    from arboretum_server.decompose import secondary as s

    d = leaf_on_pine
    zone = s.zones(d.points, [lb.members for lb in d.lobes])
    r = s._Route(d.points, d.adjacency, d.root_index, zone, None, None, 0.0, None, None, None, {}, None)
    for j in range(len(d.lobes) + 1):
        new, old = s.foreign_graph(r, j), _old_graph(r, j)
        assert np.array_equal(new.indptr, old.indptr) and np.array_equal(new.indices, old.indices)
        assert np.array_equal(new.data, old.data)


def _lobes(d):
    return [(lb.members.tolist(), lb.centre.tolist(), lb.hull_vertices.tolist(), lb.hull_faces.tolist(),
             lb.segment.tolist(), lb.parent, lb.parent_vertex) for lb in d.lobes]


def _most_taken(d) -> int:
    """The bench row's lobe (even ``j``) whose "around" selection takes points from the most lobes (the first among
    equals): each of them is rebuilt and most are routed again, the slow tail of the row."""
    return max(range(0, len(d.lobes), 2), key=lambda j: len(np.unique(d.lobe_of[_around(d, j)])))


def test_around_insert_reweights_once_per_round(leaf_on_pine, monkeypatch):
    """The "around" insert of the bench row's lobe that takes points from the most lobes: before session 14
    (helper-117) its routing round and each rerouted branch reweighted the whole graph; now once, with the same
    lobes as the code before gives. Lobe 34 until session 29 (10 rerouted branches, the row's slowest); session 30
    (the lobes changed with our own k-means) lobe 34's takes from 2 lobes and reroutes 2, so the lobe is searched:
    lobe 30, whose selection takes from 9 lobes and reroutes 10 branches (11 reweightings before, 1 now)."""
    from arboretum_server.decompose import refine
    from arboretum_server.decompose import secondary as s

    d = leaf_on_pine
    sel = _around(d, _most_taken(d))
    calls, rounds, reroutes = [0], [0], [0]
    plain_weighted, plain_make, plain_foreign = s.weighted, s.make_lobes, s.foreign_graph

    def counted(*a, **k):
        calls[0] += 1
        return plain_weighted(*a, **k)

    def counted_make(*a, **k):
        rounds[0] += 1
        return plain_make(*a, **k)

    def counted_foreign(*a, **k):
        reroutes[0] += 1
        return plain_foreign(*a, **k)

    monkeypatch.setattr(s, "weighted", counted)
    monkeypatch.setattr(refine, "make_lobes", counted_make)
    monkeypatch.setattr(s, "foreign_graph", counted_foreign)
    after = refine.insert_lobe(d, sel)
    assert (rounds[0], calls[0]) == (1, 1)
    assert reroutes[0] >= 5  # the slow tail: many branches routed again (lobe 30's: 10)
    monkeypatch.setattr(s, "foreign_graph", lambda r, j: _old_graph(r, j))
    before = refine.insert_lobe(d, sel)
    assert (rounds[0], calls[0]) == (2, 1 + 1 + reroutes[0])
    assert _lobes(after) == _lobes(before)
