"""Session 17: a reroute's path is the same tie-broken path whether its Dijkstra run was bounded or full
(``graph.tied_path``), so a real scan, whose points lie on a 1 mm grid and tie often, never pays a second,
full run (scan 06 at 12,000 points: 9 of 24 reroutes did before)."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.decompose import graph
from factories import hbl_arrays


@pytest.fixture(scope="module")
def scan06(scans_dir):
    return np.loadtxt(scans_dir / "06_adtree_tree7" / "06_adtree_tree7.xyz")[:, :3]


def test_tied_reroutes_of_a_real_scan_stay_bounded_and_match_full_runs(scan06, monkeypatch):
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    limits, unique = [], []
    plain_dijkstra, plain_unique = graph.dijkstra, graph.path_is_unique

    def spy(adj, **k):
        if "limit" in k:
            limits.append(k["limit"])
        return plain_dijkstra(adj, **k)

    def spy_unique(*a):
        unique.append(plain_unique(*a))
        return unique[-1]

    monkeypatch.setattr(graph, "dijkstra", spy)
    monkeypatch.setattr(graph, "path_is_unique", spy_unique)
    bounded = decompose(scan06, DecomposeOptions())
    assert bounded.stats["rerouted"] == len(limits) == len(unique) == 24
    assert all(np.isfinite(limits))  # no reroute ran Dijkstra a second time, in full
    assert unique.count(False) >= 5  # though several met a tie on their path
    monkeypatch.setattr(graph, "path_cost", lambda adj, known: np.inf)  # every reroute a full run
    full = decompose(scan06, DecomposeOptions())
    assert all(np.array_equal(a, b) for a, b in zip(hbl_arrays(bounded), hbl_arrays(full), strict=True))


def test_tied_path_walks_to_the_lowest_numbered_tied_neighbour():
    from scipy.sparse import coo_matrix

    # a 3 x 3 grid of unit edges, root in a corner: every node off the two edges has two tied predecessors
    a, b = [], []
    for r in range(3):
        for c in range(3):
            if c < 2:
                a.append(3 * r + c), b.append(3 * r + c + 1)
            if r < 2:
                a.append(3 * r + c), b.append(3 * r + c + 3)
    w = np.ones(len(a))
    adj = coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(9, 9)).tocsr()
    dist, _ = graph.shortest_paths(adj, 0)
    assert graph.tied_path(adj, dist, 0, 8).tolist() == [0, 1, 2, 5, 8]
    assert graph.tied_path(adj, dist, 0, 4).tolist() == [0, 1, 4]
    assert graph.tied_path(adj, 1.5 * dist, 0, 4) is None  # distances not of this graph: no step holds
