"""The whole-cloud KD-tree queries run on every core past ``graph.PARALLEL_MIN`` points, with the same answer."""

import signal
import threading

import numpy as np
import pytest
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
    """A stand-in KD-tree that records the ``workers`` it was asked with, and can send itself a SIGINT."""

    def __init__(self, interrupt: bool = False) -> None:
        self.workers: list[int] = []
        self.interrupt = interrupt

    def query(self, q, workers=1, **kw):
        if self.interrupt:
            signal.raise_signal(signal.SIGINT)
        self.workers.append(workers)  # reached: the signal did not cut the query short
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


def test_a_ctrl_c_during_a_parallel_query_waits_for_its_end(monkeypatch):
    """scipy's worker threads ran on after a Ctrl-C ended the wait for them, and the interpreter crashed
    shutting down under them: the interrupt now comes after the query, to the handler that was there."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    before = signal.getsignal(signal.SIGINT)
    tree = _Recorder(interrupt=True)
    with pytest.raises(KeyboardInterrupt):
        graph.query(tree, np.zeros((graph.PARALLEL_MIN, 3)))
    assert tree.workers == [-1] and signal.getsignal(signal.SIGINT) is before
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a handler that ignores it still does
    try:
        graph.query(tree, np.zeros((graph.PARALLEL_MIN, 3)))
        assert tree.workers == [-1, -1] and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


def test_a_query_off_the_main_thread_leaves_signals_alone(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    tree, errors = _Recorder(), []

    def run():
        try:
            graph.query(tree, np.zeros((graph.PARALLEL_MIN, 3)))
        except Exception as exc:  # signal.signal off the main thread would raise ValueError
            errors.append(exc)

    t = threading.Thread(target=run)
    t.start()
    t.join()
    assert errors == [] and tree.workers == [-1]
