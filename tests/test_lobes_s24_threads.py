"""Session 24: a decomposition is the same bit for bit whatever the number of OpenMP threads.

scikit-learn's k-means sums each thread's share of the points apart, so with two threads its centres
differed in their last bits from one thread's, and every lobe after them: `arboretum decompose` on a
2-core machine and a batch worker (one thread) gave two libraries from one scan. `lobes.kmeans` and the
module exporter's clustering now run on one thread (`lobes.KMEANS_THREADS`)."""

from __future__ import annotations

import numpy as np
import pytest
import sklearn.cluster  # noqa: F401  (loads scikit-learn's OpenMP runtime, so the limits below reach it)
from threadpoolctl import threadpool_limits

from arboretum_server.decompose import lobes
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from arboretum_server.decompose.toytree import toy_scan, toy_truth


@pytest.fixture(scope="module")
def cloud() -> np.ndarray:
    pts, _ = toy_scan(toy_truth(), n=12000, seed=1)
    return pts


def _kmeans_under(threads: int, pts: np.ndarray):
    with threadpool_limits(limits=threads, user_api="openmp"):
        return lobes.kmeans(pts, 40, np.random.default_rng(7))


def test_kmeans_centres_do_not_depend_on_threads():
    blob = np.random.default_rng(1).normal(size=(20000, 3))  # two threads moved these centres' last bits
    one, two = _kmeans_under(1, blob), _kmeans_under(2, blob)
    assert np.array_equal(one[0], two[0])
    assert one[1].tobytes() == two[1].tobytes()
    assert one[1].shape == (40, 3) and len(np.unique(one[0])) == 40


def test_decomposition_does_not_depend_on_threads(cloud):
    def run(threads: int):
        with threadpool_limits(limits=threads, user_api="openmp"):
            return decompose(cloud, DecomposeOptions(seed=3))

    one, two = run(1), run(2)
    assert np.array_equal(one.lobe_of, two.lobe_of)
    assert len(one.lobes) == len(two.lobes) == 40
    for a, b in zip(one.hbl.lobes, two.hbl.lobes):
        assert a.points.tobytes() == b.points.tobytes()
    for a, b in zip(one.hbl.branches, two.hbl.branches):
        assert a.points.tobytes() == b.points.tobytes()
