"""A lone stray point far from the tree (a noisy return, a bird) is left out before the trunk base and
the height are found (``preprocess.strays``): 10 m under scan 07 it became the trunk base (the root moved
9.8 m, the tree measured 34.3 m instead of 24.5 m), and 10 m above it stretched the height."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.decompose.notes import scan_notes
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.preprocess import prepare, strays
from arboretum_server.decompose.toytree import toy_scan, toy_truth

OPTS = DecomposeOptions(n_main=3, n_lobes=6, points=0)


@pytest.fixture(scope="module")
def tree() -> np.ndarray:
    pts, _ = toy_scan(toy_truth(), n=6000, seed=5)
    return pts


def _prepared(pts):
    return prepare(pts, OPTS, np.random.default_rng(0))


@pytest.mark.parametrize("where", [(0.0, 0.0, -0.5), (0.0, 0.0, 2.0), (1.5, 0.0, 0.3)])  # under, over, beside
def test_one_stray_point_changes_neither_root_nor_height(tree, where):
    base = _prepared(tree)
    h = float(np.ptp(tree[:, 2]))
    stray = tree[np.argmin(tree[:, 2])] + np.asarray(where) * h  # 0.5 height under the lowest point, ...
    p = _prepared(np.vstack([tree, stray]))
    assert p.strays == 1 and len(p.points) == len(base.points) and base.strays == 0
    assert np.array_equal(p.root_scan, base.root_scan) and p.scale == base.scale
    assert len(tree) not in p.source_index  # the stray's row


def test_a_few_strays_together_are_left_out_and_named(tree):
    h = float(np.ptp(tree[:, 2]))
    bird = tree[np.argmax(tree[:, 2])] + [0.0, 0.0, 0.6 * h] + np.random.default_rng(1).normal(0, 0.002 * h, (4, 3))
    p = _prepared(np.vstack([tree, bird]))
    assert p.strays == 4
    assert scan_notes({"strays": 4})[0].startswith("4 stray points left out: each stands over a tenth")


def test_five_points_together_are_no_strays(tree):
    h = float(np.ptp(tree[:, 2]))
    group = tree[np.argmax(tree[:, 2])] + [0.0, 0.0, 0.6 * h] + np.random.default_rng(1).normal(0, 0.002 * h, (5, 3))
    assert not strays(np.vstack([tree, group]))[-5:].any()


def test_a_sparse_cloud_has_no_strays():
    rng = np.random.default_rng(2)
    sparse = np.c_[rng.normal(0, 2, (120, 2)), rng.uniform(0, 6, 120)]  # a photo cloud's spacing
    assert not strays(sparse).any()
    assert not strays(sparse[:40]).any()  # too few points to judge


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_cell_search_for_large_clouds_finds_what_the_exact_one_does(seed):
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.preprocess import _apart

    rng = np.random.default_rng(seed)
    cloud = np.vstack([rng.normal(0, 1, (20000, 3)) * [1, 1, 3],  # a crowd, then sparse points around it at
                       rng.uniform(-12, 12, (300, 3))])  # every distance from the far threshold
    far = float(rng.uniform(0.8, 2.0))
    exact = cKDTree(cloud).query(cloud, 5)[0][:, -1] > far  # fewer than 4 others within far
    fast = _apart(cloud, far, 5)
    assert 10 < exact.sum() < 1000 and np.array_equal(fast, exact)


def test_a_large_cloud_takes_the_cell_search(tree, monkeypatch):
    from arboretum_server.decompose import preprocess

    big = np.vstack([tree] * 10) + np.random.default_rng(3).normal(0, 1e-4, (10 * len(tree), 3))
    stray = big[np.argmin(big[:, 2])] - [0.0, 0.0, 0.5 * float(np.ptp(big[:, 2]))]
    called, real = [], preprocess._apart
    monkeypatch.setattr(preprocess, "_apart", lambda *a: called.append(1) or real(*a))
    out = preprocess.strays(np.vstack([big, stray]))
    assert called == [1] and np.flatnonzero(out).tolist() == [len(big)]



def test_a_cloud_too_wide_for_cell_keys_is_looked_up_whole():
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.preprocess import _apart

    rng = np.random.default_rng(5)
    cloud = np.vstack([rng.normal(0, 1e-3, (3000, 3)), [[1e11, 1e11, 0.0]], rng.normal(0, 1e-3, (3000, 3)) + [0, 0, 0.01]])
    exact = cKDTree(cloud).query(cloud, 5)[0][:, -1] > 0.001
    assert np.array_equal(_apart(cloud, 0.001, 5), exact) and exact[3000]
