"""Session 15 (helper-119): a rerouted secondary branch needs only the path to its own lobe, so its Dijkstra
stops at the length of the shared routing's path re-priced on the reroute's graph
(``graph.shortest_path_to``). The path must be the full run's, node for node, and so must every
decomposition; where two neighbours give a node of that path the same distance, the lower-numbered one is
taken (session 17, ``graph.tied_path``: before, the full run decided)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix

from arboretum_server.decompose import graph
from arboretum_server.decompose.graph import (
    path_cost,
    path_is_unique,
    path_to,
    shortest_path_to,
    shortest_paths,
)
from factories import hbl_arrays

MIN_REROUTES = 20
"""The fewest reroutes the leaf-on pine's decomposition must make for the shared-Dijkstra test to mean
something (36 before session 30, 35 after)."""


def _tied_graph(rng: np.random.Generator, n: int):
    """A connected symmetric graph on ``n`` nodes with weights 1, 2 or 3 (times 0.1 or 1): many exact ties."""
    m = 3 * n
    a, b = rng.integers(0, n, m), rng.integers(0, n, m)
    a, b = a[a != b], b[a != b]
    w = rng.integers(1, 4, len(a)) * (0.1 if rng.random() < 0.5 else 1.0)
    chain = np.arange(n - 1)
    a, b, w = np.r_[a, chain], np.r_[b, chain + 1], np.r_[w, np.full(n - 1, 2.0)]
    adj = coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(n, n)).tocsr()
    adj.sum_duplicates()
    return adj


def _lowest_tied_path(adj, dist, root, target):
    """The reference: from ``target`` back to ``root``, each step to the lowest-numbered neighbour whose
    distance plus edge gives the node's own, on a dense copy of the graph."""
    a = adj.toarray()
    out = [target]
    while out[-1] != root:
        v = out[-1]
        out.append(min(u for u in range(len(a)) if a[v, u] > 0 and dist[u] + a[v, u] == dist[v] and dist[u] < dist[v]))
    return out[::-1]


def test_bounded_path_equals_full_run_on_tied_graphs():
    rng = np.random.default_rng(0)
    checked = tied = 0
    for _ in range(200):
        n = int(rng.integers(20, 300))
        adj = _tied_graph(rng, n)
        root = int(rng.integers(n))
        dist, pred = shortest_paths(adj, root)
        for target in rng.integers(0, n, 4).tolist():
            want = _lowest_tied_path(adj, dist, root, target)
            tied += want != path_to(pred, target).tolist()
            for known in (path_to(pred, target), np.array([root, target])):  # tight, and too short (full run)
                assert path_to(shortest_path_to(adj, root, target, known), target).tolist() == want
                checked += 1
    assert checked == 1600
    assert tied > 50  # Dijkstra's own order took another tied neighbour on many of these paths


def _square():
    """Root 0 to target 3 two ways of the same length (0-1-3, 0-2-3), and a far node 4 behind the target."""
    a, b, w = np.array([0, 0, 1, 2, 3]), np.array([1, 2, 3, 3, 4]), np.array([1.0, 1.0, 1.0, 1.0, 5.0])
    return coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(5, 5)).tocsr()


def test_a_tie_on_the_path_takes_the_lower_numbered_node_without_a_full_run(monkeypatch):
    limits = []
    plain = graph.dijkstra

    def spy(*a, **k):
        limits.append(k.get("limit", np.inf))
        return plain(*a, **k)

    monkeypatch.setattr(graph, "dijkstra", spy)
    for adj in (_square(), _square()[[0, 2, 1, 3, 4]][:, [0, 2, 1, 3, 4]].tocsr()):  # and with 1 and 2 swapped
        dist, pred = shortest_paths(adj, 0)
        assert not path_is_unique(adj, dist, path_to(pred, 3))  # nodes 1 and 2 both give node 3 its distance
        limits.clear()
        got = shortest_path_to(adj, 0, 3, path_to(pred, 3))
        assert limits == [2.0]  # bounded at the path's length 2, and no full run
        assert path_to(got, 3).tolist() == [0, 1, 3]
    limits.clear()
    got = shortest_path_to(adj, 0, 1, np.array([0, 1]))
    assert limits == [1.0] and got.tolist()[:2] == [-1, 0]


def test_a_bound_too_short_runs_in_full_and_an_unreachable_target_is_named():
    adj = _square()
    got = shortest_path_to(adj, 0, 4, np.array([0, 4]))  # no such edge: costs 0, below the distance 7
    assert path_to(got, 4).tolist() == [0, 1, 3, 4]
    cut = coo_matrix((np.ones(2), ([0, 1], [1, 0])), shape=(3, 3)).tocsr()
    with pytest.raises(ValueError, match="node 2 is not reachable from node 0"):
        shortest_path_to(cut, 0, 2, np.array([0, 2]))


def test_path_cost_sums_from_the_root_and_bounds_the_distance():
    adj = _square()
    assert path_cost(adj, np.array([0, 1, 3, 4])) == 7.0
    assert path_cost(adj, np.array([4])) == 0.0
    rng = np.random.default_rng(3)
    for _ in range(50):
        adj = _tied_graph(rng, 100)
        adj.data = adj.data * rng.uniform(0.5, 2.0, len(adj.data))  # asymmetric rounding, still >= Dijkstra
        adj = (adj + adj.T).tocsr()
        dist, pred = shortest_paths(adj, 0)
        for t in range(100):
            assert path_cost(adj, path_to(pred, t)) >= dist[t]


def test_path_to_reads_an_array_like_a_list():
    pred = np.array([-1, 0, 1, 1, 3], np.int32)
    assert path_to(pred, 4).tolist() == path_to(pred.tolist(), 4).tolist() == [0, 1, 3, 4]
    assert path_to(pred, 0).tolist() == [0]


@pytest.fixture(scope="module")
def pine_points():
    from arboretum_server.decompose.report import CASES, grow_truth
    from arboretum_server.decompose.toytree import toy_scan

    truth = grow_truth("harmonic", "pine", 1)
    pts, _ = toy_scan(truth, n=40000, noise=0.002 * float(np.ptp(truth.positions[:, 2])), seed=1,
                      **CASES["leaf-on"])
    return pts


def test_reroutes_are_bounded_and_change_nothing(pine_points, monkeypatch):
    """The leaf-on pine reroutes many branches (36 before session 30, 35 with the lobes of our own k-means):
    since session 24 they share one more Dijkstra (the graph with every zone foreign,
    ``secondary._reroute_path``), each repaired over its own lobe's zone edges, and the decomposition equals the
    one with a full run per reroute. Session 30: the count is read from the decomposition (at least
    ``MIN_REROUTES``) instead of fixed at 36, so a change of lobes does not break the test; the full runs must
    still be one per reroute and the shared ones still 3 in all."""
    from arboretum_server.decompose import secondary
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    runs = []
    plain = graph.dijkstra

    def spy(adj, **k):
        dist, pred = plain(adj, **k)
        runs.append((k.get("limit", np.inf), int(np.isfinite(dist).sum()), adj.shape[0]))
        return dist, pred

    monkeypatch.setattr(graph, "dijkstra", spy)
    shared = decompose(pine_points, DecomposeOptions(species="pine"))
    rerouted = shared.stats["rerouted"]  # 35 today
    assert rerouted >= MIN_REROUTES and len(runs) == 3  # mains, shared routing, the all-foreign run
    full_path = lambda r, j, adj, target: path_to(shortest_paths(adj, r.root)[1], target)  # noqa: E731
    monkeypatch.setattr(secondary, "_reroute_path", full_path)
    full = decompose(pine_points, DecomposeOptions(species="pine"))
    assert full.stats["rerouted"] == rerouted and len(runs) == 3 + 2 + rerouted
    assert all(np.array_equal(a, b) for a, b in zip(hbl_arrays(shared), hbl_arrays(full), strict=True))
