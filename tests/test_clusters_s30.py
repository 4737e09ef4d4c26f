"""Session 30: the lobes' k-means is our own (`decompose.clusters`), not scikit-learn's `KMeans`, whose import
cost every `arboretum decompose` 0.9-1.3 s. These tests hold what the lobes need of it: Lloyd's fixed point,
k-means++ seeding that finds separate groups, the same answer from the same generator, and no scikit-learn."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from arboretum_server.decompose import clusters


def _blobs(k: int, per: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-10, 10, (k, 3)) * np.arange(1, k + 1)[:, None]  # far apart
    truth = np.repeat(np.arange(k), per)
    return centres[truth] + rng.normal(scale=0.05, size=(k * per, 3)), truth


def test_separate_groups_come_out_as_they_are():
    # k-means++ puts one seed in each far-apart blob (the plain random start of k-means misses some)
    pts, truth = _blobs(12, 40, seed=4)
    labels, centres = clusters.kmeans(pts, 12, np.random.default_rng(0))
    assert labels.dtype == np.int32 and centres.shape == (12, 3)
    pairs = set(zip(truth.tolist(), labels.tolist()))
    assert len(pairs) == 12 and len({b for _, b in pairs}) == 12  # one cluster per blob, every blob whole


def test_the_result_is_lloyds_fixed_point():
    # each centre is the mean of its points and each point lies nearest its own centre
    pts = np.random.default_rng(5).normal(size=(3000, 3)) * [3.0, 1.0, 0.5]
    labels, centres = clusters.kmeans(pts, 25, np.random.default_rng(1))
    assert sorted(np.unique(labels).tolist()) == list(range(25))
    means = np.array([pts[labels == c].mean(axis=0) for c in range(25)])
    assert np.abs(means - centres).max() < 0.05 * np.abs(centres).max()  # stopped on the small shift rule or
    d = np.linalg.norm(pts[:, None] - centres[None], axis=2)  # on no label changing: within the tolerance
    assert np.array_equal(np.argmin(d, axis=1), labels)


def test_the_same_generator_gives_the_same_bits_and_the_caller_draws_once():
    pts = np.random.default_rng(6).normal(size=(2000, 3))
    a = clusters.kmeans(pts, 30, np.random.default_rng(9))
    b = clusters.kmeans(pts, 30, np.random.default_rng(9))
    c = clusters.kmeans(pts, 30, np.random.default_rng(10))
    assert np.array_equal(a[0], b[0]) and a[1].tobytes() == b[1].tobytes()
    assert not np.array_equal(a[0], c[0])
    from arboretum_server.decompose.lobes import kmeans

    rng = np.random.default_rng(3)
    kmeans(pts, 5, rng)  # lobes.kmeans takes one integer from the pipeline's generator, as it did before
    twin = np.random.default_rng(3)
    twin.integers(2**31 - 1)
    assert rng.integers(1 << 30) == twin.integers(1 << 30)


def test_more_clusters_than_distinct_points_and_given_starts():
    pts = np.r_[np.zeros((5, 3)), np.ones((5, 3))]
    labels, centres = clusters.kmeans(pts, 4, np.random.default_rng(0))
    assert centres.shape == (4, 3) and set(np.unique(labels).tolist()) <= {0, 1, 2, 3}
    assert len(np.unique(labels)) == 2 and np.isfinite(centres).all()
    assert clusters.kmeans(pts, 20, np.random.default_rng(0))[1].shape == (10, 3)  # k capped at the points
    labels, centres = clusters.kmeans(pts, 2, np.random.default_rng(0), init=np.array([[2.0, 2, 2], [-1.0, -1, -1]]))
    assert labels.tolist() == [1] * 5 + [0] * 5 and np.allclose(centres, [[1, 1, 1], [0, 0, 0]])
    with pytest.raises(ValueError, match="non-empty"):
        clusters.kmeans(np.zeros((0, 3)), 3, np.random.default_rng(0))
    with pytest.raises(ValueError, match="3 starting centres for 2 clusters"):
        clusters.kmeans(pts, 2, np.random.default_rng(0), init=np.zeros((3, 3)))


def test_a_decomposition_imports_no_scikit_learn():
    code = ("import sys\nfrom arboretum_server.decompose.pipeline import decompose\n"
            "from arboretum_server.decompose.toytree import toy_scan, toy_truth\n"
            "decompose(toy_scan(toy_truth(), n=3000, seed=1)[0])\n"
            "print('sklearn' in sys.modules, 'scipy.stats' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.stdout.split() == ["False", "False"], out.stderr[-2000:]
