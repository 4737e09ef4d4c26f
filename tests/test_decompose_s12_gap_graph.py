"""``graph.gap_graph`` on clouds of many components (helper-92's hunt, session 12): scan 06 with every
point given 6 times 0.5 mm apart (`--points 0`) left each point a component of its copies, 15,130 of
them; pairing every two components ran 27.8 M k-d tree queries and ended after 4 min in a MemoryError
traceback. Past ``MAX_PAIRS_COMPONENTS`` components, or ``QUERY_BUDGET`` queries per point, only the
components holding ``BIG`` of the points are paired; below, the graph is the one every pair gives."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from arboretum_server.decompose import graph
from arboretum_server.decompose.graph import SHORTCUT_COST, SHORTCUT_REACH, gap_graph, knn_graph


def _every_pair(points, g, radius):
    """The shortcut edges (i, j) -> length every pair of components gives (the rule before session 12)."""
    lab = g.component
    groups = [np.flatnonzero(lab == c) for c in range(lab.max() + 1)]
    reach = SHORTCUT_REACH * radius
    out = {}
    for i in range(len(groups)):
        for j in range(i + 1, len(groups)):
            pi, pj = points[groups[i]], points[groups[j]]
            if not ((pi.min(0) - reach <= pj.max(0)) & (pj.min(0) - reach <= pi.max(0))).all():
                continue
            small, big = (groups[i], groups[j]) if len(groups[i]) <= len(groups[j]) else (groups[j], groups[i])
            d, k = cKDTree(points[big]).query(points[small], distance_upper_bound=reach)
            for a, b, w in zip(small[np.isfinite(d)], big[k[np.isfinite(d)]], d[np.isfinite(d)]):
                out[(min(a, b), max(a, b))] = w
    return out


def _clusters(n, copies, rng, spread=1.0):
    centres = rng.uniform(0, spread, (n, 3))
    return np.repeat(centres, copies, axis=0) + rng.normal(0, 1e-5, (n * copies, 3))


def test_a_few_components_give_the_edges_of_every_pair():
    rng = np.random.default_rng(4)
    pts = np.vstack([rng.uniform(0, 0.3, (400, 3)) + [k * 0.12, 0, 0] for k in range(4)]
                    + [rng.uniform(0, 0.02, (12, 3)) + [0.2, 0.35, 0.1]])  # and a small one above
    g = knn_graph(pts, 5, 0.05)
    assert 2 <= g.components <= 40
    gaps = gap_graph(pts, g, 0.05).tocoo()
    across = g.component[gaps.row] != g.component[gaps.col]
    want = _every_pair(pts, g, 0.05)
    got = {(min(a, b), max(a, b)): w / SHORTCUT_COST for a, b, w in zip(gaps.row[across], gaps.col[across], gaps.data[across])}
    bridges = {k for k in got if k not in want}  # the bridges of knn_graph are gap edges too
    assert len(bridges) <= g.bridges
    assert all(np.isclose(got[k], w) for k, w in want.items() if k in got) and set(want) <= set(got)


def test_near_duplicates_are_paired_only_among_big_components():
    rng = np.random.default_rng(5)
    slab = rng.uniform(0, 0.8, (2000, 3)) * [0.05, 0.05, 1]  # two big pieces 6 cm apart, among the copies
    pts = np.vstack([_clusters(3000, 6, rng, 0.8), slab, slab + [0.11, 0.0, 0.0]])
    g = knn_graph(pts, 5, 0.05)
    assert g.components > graph.MAX_PAIRS_COMPONENTS
    gaps = gap_graph(pts, g, 0.05)
    sizes = np.bincount(g.component)
    e = gaps.tocoo()
    across = g.component[e.row] != g.component[e.col]
    bridge = np.asarray(g.adjacency[e.row, e.col]).ravel() > 0
    big = sizes >= graph.BIG * len(pts)
    # a gap edge is one of knn_graph's bridges or joins two big components
    assert (across & ~bridge & ~(big[g.component[e.row]] & big[g.component[e.col]])).sum() == 0
    assert big.sum() == 2 and (across & ~bridge).sum() > 0  # the two big pieces are joined by shortcuts


def test_pairs_over_the_query_budget_fall_back_to_big_components(monkeypatch):
    rng = np.random.default_rng(6)
    pts = np.vstack([_clusters(60, 6, rng, 0.3), rng.uniform(0, 0.3, (600, 3))])
    g = knn_graph(pts, 5, 0.05)
    groups = np.split(np.argsort(g.component, kind="stable"), np.cumsum(np.bincount(g.component))[:-1])
    every = graph._near_pairs(pts, groups, SHORTCUT_REACH * 0.05)
    monkeypatch.setattr(graph, "QUERY_BUDGET", 0)
    few = graph._near_pairs(pts, groups, SHORTCUT_REACH * 0.05)
    big = {i for i, ix in enumerate(groups) if len(ix) >= graph.BIG * len(pts)}
    assert len(every) > len(few) and all(i in big and j in big for i, j in few)
