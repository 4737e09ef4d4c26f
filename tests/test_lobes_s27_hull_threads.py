"""Session 27: the plain hulls of ``secondary._hulled`` are built on every core (``lobes.plain_hulls``).

qhull and the compiled alpha-shape loops release the GIL, so a refinement's or a decomposition's hulls are
built in threads; the results must be the same arrays in the same order as one thread's, ``OMP_NUM_THREADS``
caps the threads (a batch worker's 1: no pool at all), and a Ctrl-C during the pool stops it with no thread
left running."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

from arboretum_server.decompose import carve, lobes, secondary
from arboretum_server.decompose.toytree import toy_scan, toy_truth


@pytest.fixture(scope="module")
def groups() -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The toy tree's 12,000 points, 24 k-means groups of them (sizes differ) and their centres."""
    pts, _ = toy_scan(toy_truth(), n=12000, seed=1)
    lab, centres = lobes.kmeans(pts, 24, np.random.default_rng(5))
    return pts, [np.flatnonzero(lab == k) for k in range(len(centres))], centres


def _same(a: tuple, b: tuple) -> bool:
    return (a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes() and a[2] == b[2] and a[3] == b[3]
            and a[4].tets.tobytes() == b[4].tets.tobytes())


@pytest.fixture
def two_threads(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    monkeypatch.setattr(lobes, "HULL_POOL_MEAN", 0)


def test_threaded_hulls_equal_one_threads_in_order(groups, two_threads, monkeypatch):
    pts, gs, _ = groups
    sets = [pts[g] for g in gs]
    names = set()
    plain = lobes.plain_hull

    def watched(p, r):
        names.add(threading.current_thread().name)
        return plain(p, r)

    monkeypatch.setattr(lobes, "plain_hull", watched)
    threaded = lobes.plain_hulls(sets, 1 / 13)
    assert "MainThread" in names and any(n.startswith("plain_hulls") for n in names)  # this thread and the pool's
    one = [plain(p, 1 / 13) for p in sets]
    assert len(threaded) == len(one) == 24
    assert all(_same(a, b) for a, b in zip(threaded, one))
    assert not _same(threaded[0], one[1])  # the hulls differ from group to group, so an order mix-up shows
    assert sum(h[2] for h in one) >= 12  # most are alpha shapes, not convex hulls


def test_one_thread_starts_no_pool(groups, monkeypatch):
    pts, gs, _ = groups
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    monkeypatch.setattr(lobes, "HULL_POOL_MEAN", 0)
    monkeypatch.setattr(lobes, "ThreadPoolExecutor", None)  # a pool would fail
    hulls = lobes.plain_hulls([pts[g] for g in gs[:4]], 1 / 13)
    assert len(hulls) == 4


def test_small_batches_start_no_pool(groups, monkeypatch):
    pts, gs, _ = groups
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    monkeypatch.setattr(lobes, "ThreadPoolExecutor", None)
    sets = [pts[g[:10]] for g in gs[:20]]  # a split's 20 pieces: 200 points in all
    assert sum(len(p) for p in sets) < lobes.HULL_POOL_MEAN * 20
    assert len(lobes.plain_hulls(sets, 1 / 13)) == 20
    assert len(lobes.plain_hulls([pts[gs[0]]] + sets, 1 / 13)) == 21  # one large hull among them: still small
    assert len(lobes.plain_hulls([pts[gs[0]]], 1 / 13)) == 1  # one hull: no pool


def test_hull_threads_honour_omp_num_threads(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert lobes.hull_threads() == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert lobes.hull_threads() == 3
    for value in ("", "0", "two"):
        monkeypatch.setenv("OMP_NUM_THREADS", value)
        assert lobes.hull_threads() == len(os.sched_getaffinity(0))
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert lobes.hull_threads() == len(os.sched_getaffinity(0))


def test_hulled_remembers_each_groups_tetrahedra(groups, two_threads):
    pts, gs, centres = groups
    kept = secondary._hulled(gs[:1], centres[:1], pts, (), 1 / 13)[0]
    out = secondary._hulled(gs, centres, pts, (kept,), 1 / 13)
    assert [lb.members is g for lb, g in zip(out, gs)] == [True] * 24
    assert out[0].hull_vertices is kept.hull_vertices  # a kept hull is not built again
    for g, lb in zip(gs[1:], out[1:]):
        v, f, used, steps, tet = lobes.plain_hull(pts[g], 1 / 13)
        assert lb.hull_vertices.tobytes() == v.tobytes() and lb.hull_faces.tobytes() == f.tobytes()
        assert (lb.alpha, lb.steps) == (used, steps)
        assert carve._recall_plain(g, pts[g]).tets.tobytes() == tet.tets.tobytes()


def test_ctrl_c_during_the_pool_stops_it_with_no_thread_left(groups, two_threads, monkeypatch):
    pts, gs, _ = groups
    calls = []
    plain = lobes.plain_hull

    def interrupted(p, r):
        calls.append(1)
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)  # the hulls still under way when the interrupt is seen take a while
        return plain(p, r)

    monkeypatch.setattr(lobes, "plain_hull", interrupted)
    with pytest.raises(KeyboardInterrupt):
        lobes.plain_hulls([pts[g] for g in gs], 1 / 13)
    assert 3 <= len(calls) < 24  # the hulls not started were dropped
    assert not [t for t in threading.enumerate() if t.name.startswith("plain_hulls")]
    n = len(calls)
    time.sleep(0.2)
    assert len(calls) == n
