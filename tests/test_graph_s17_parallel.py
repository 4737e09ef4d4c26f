"""The whole-cloud KD-tree queries run on every core past ``graph.PARALLEL_MIN`` points, with the same answer."""

import numpy as np
from scipy.spatial import cKDTree

from arboretum_server.decompose import graph


def _cloud(n: int) -> np.ndarray:
    rng = np.random.default_rng(17)
    return np.round(rng.random((n, 3)), 3)  # a 1 mm grid: many exact ties, as on the real scans


def test_parallel_query_matches_one_core_past_the_threshold():
    pts = _cloud(graph.PARALLEL_MIN + 1000)
    tree = cKDTree(pts)
    d1, i1 = tree.query(pts, k=6, workers=1)
    d2, i2 = graph.query(tree, pts, k=6)
    assert d2.shape == (len(pts), 6)
    np.testing.assert_array_equal(d1, d2)
    np.testing.assert_array_equal(i1, i2)


def test_parallel_query_keeps_the_upper_bound():
    pts = _cloud(graph.PARALLEL_MIN)
    tree = cKDTree(pts[::7])
    d1, i1 = tree.query(pts, distance_upper_bound=0.004, workers=1)
    d2, i2 = graph.query(tree, pts, distance_upper_bound=0.004)
    np.testing.assert_array_equal(d1, d2)
    np.testing.assert_array_equal(i1, i2)
    assert 0 < np.isinf(d2).sum() < len(pts)  # the bound cut some answers and kept others


def test_knn_graph_the_same_either_side_of_the_threshold(monkeypatch):
    pts = _cloud(60_000)
    parallel = graph.knn_graph(pts, 5, 0.01)
    monkeypatch.setattr(graph, "PARALLEL_MIN", 10**9)
    serial = graph.knn_graph(pts, 5, 0.01)
    assert parallel.components == serial.components > 1
    assert parallel.bridges == serial.bridges
    assert (parallel.adjacency != serial.adjacency).nnz == 0
    np.testing.assert_array_equal(parallel.neighbours, serial.neighbours)


class _Recorder:
    """A stand-in KD-tree that records the ``workers`` it was asked with."""

    def __init__(self) -> None:
        self.workers: list[int] = []

    def query(self, q, workers=1, **kw):
        self.workers.append(workers)
        return np.zeros(len(q)), np.zeros(len(q), int)


def test_threads_follow_omp_num_threads(monkeypatch):
    big, small = np.zeros((graph.PARALLEL_MIN, 3)), np.zeros((10, 3))
    tree = _Recorder()
    for value, want in (("1", 1), ("3", 3), ("0", -1), ("many", -1), ("", -1)):
        monkeypatch.setenv("OMP_NUM_THREADS", value)
        graph.query(tree, big)
        graph.query(tree, small)
        assert tree.workers[-2:] == [want, 1]
    monkeypatch.delenv("OMP_NUM_THREADS")
    graph.query(tree, big)
    assert tree.workers[-1] == -1
