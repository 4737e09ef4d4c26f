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


def test_around_insert_reweights_once_per_round(leaf_on_pine, monkeypatch):
    """Lobe 34's "around" insert (the bench row's slowest, 117 ms before): its routing round and 10 rerouted
    branches reweighted the whole graph 11 times; now once, with the same lobes as the code before gives."""
    from arboretum_server.decompose import refine
    from arboretum_server.decompose import secondary as s

    d = leaf_on_pine
    sel = _around(d, 34)
    calls, rounds = [0], [0]
    plain_weighted, plain_make = s.weighted, s.make_lobes

    def counted(*a, **k):
        calls[0] += 1
        return plain_weighted(*a, **k)

    def counted_make(*a, **k):
        rounds[0] += 1
        return plain_make(*a, **k)

    monkeypatch.setattr(s, "weighted", counted)
    monkeypatch.setattr(refine, "make_lobes", counted_make)
    after = refine.insert_lobe(d, sel)
    assert (rounds[0], calls[0]) == (1, 1)
    monkeypatch.setattr(s, "foreign_graph", lambda r, j: _old_graph(r, j))
    before = refine.insert_lobe(d, sel)
    assert (rounds[0], calls[0]) == (2, 1 + 11)
    assert _lobes(after) == _lobes(before)
