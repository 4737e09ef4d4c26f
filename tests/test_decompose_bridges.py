"""Bridging a kNN graph split into many components (full-resolution scans): each lonely component's
shortest edge to the rest, found through the outsiders near it (``graph._nearest_pair``), is the
brute-force one."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from arboretum_server.decompose import graph
from arboretum_server.decompose.graph import _nearest_pair, knn_graph, nearest_pair_reference


def _brute(points, inside, lab, c):
    out = np.flatnonzero(lab != c)
    d = np.linalg.norm(points[inside][:, None] - points[out][None], axis=2)
    r, k = np.unravel_index(int(np.argmin(d)), d.shape)
    return inside[r], out[k], d[r, k]


@pytest.mark.parametrize("size", [3, 40, 300, 2000, 2500])
def test_a_lonely_components_nearest_pair_is_the_brute_force_one(rng, size):
    # a dense blob (the component) among scattered clusters: its interior points' nearest neighbours
    # are all its own, so the search must widen past them without missing the true shortest edge
    blob = rng.normal(0, 0.01, (size, 3))
    others = rng.normal(0, 0.08, (1500, 3)) + [0.1, 0, 0]
    points = np.vstack([blob, others])
    lab = np.r_[np.zeros(size, int), 1 + rng.integers(0, 20, 1500)]
    inside = np.arange(size)
    a, b, w = _nearest_pair(points, cKDTree(points), inside, lab, 0)
    ea, eb, ew = _brute(points, inside, lab, 0)
    assert (a[0], b[0]) == (ea, eb) and w[0] == pytest.approx(ew, rel=1e-12)
    ra, rb, rw = nearest_pair_reference(points, None, inside, lab, 0)
    assert (ra[0], rb[0]) == (ea, eb) and rw[0] == pytest.approx(ew, rel=1e-12)


def test_many_lonely_components_are_bridged_by_their_shortest_edges(rng):
    # 150 blobs of 30-200 points on a line, 4 cm apart: K = 5 neighbours never leave a blob, and the
    # bridges must be the shortest edges between neighbouring blobs (the minimum spanning tree)
    centres = np.c_[np.arange(150) * 0.04, np.zeros(150), np.zeros(150)]
    blobs = [c + rng.normal(0, 0.003, (int(rng.integers(30, 200)), 3)) for c in centres]
    pts = np.vstack(blobs)
    lab = np.repeat(np.arange(150), [len(b) for b in blobs])
    g = knn_graph(pts, 5, 0.05)
    assert g.components == 150 and g.bridges == 149
    assert connected_components(g.adjacency, directed=False)[0] == 1
    coo = g.adjacency.tocoo()
    across = (lab[coo.row] != lab[coo.col]) & (coo.row < coo.col)
    got = sorted(zip(np.minimum(lab[coo.row], lab[coo.col])[across], coo.data[across]))
    want = [(i, cKDTree(blobs[i]).query(blobs[i + 1])[0].min()) for i in range(149)]
    assert [i for i, _ in got] == list(range(149))
    np.testing.assert_allclose([w for _, w in got], [w for _, w in want], rtol=1e-12)


def test_the_graph_is_the_one_the_reference_bridging_gives(rng, monkeypatch):
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts, _ = toy_scan(toy_truth(), n=40_000, seed=1)
    pts = (pts - pts.min(axis=0)) / np.ptp(pts[:, 2]) * 0.8
    g = knn_graph(pts, 5, 0.05)
    monkeypatch.setattr(graph, "_nearest_pair", nearest_pair_reference)
    ref = knn_graph(pts, 5, 0.05)
    assert g.components == ref.components > 500  # a full-resolution toy scan: hundreds of pieces
    assert (g.adjacency != ref.adjacency).nnz == 0


@pytest.mark.parametrize("seed", range(5))
def test_a_straight_pole_in_runs_is_bridged(seed, monkeypatch):
    # 12 exactly collinear runs of 20 points with 4 cm gaps: each run's extreme point is a corner of
    # its box, so the bound's outsider lies exactly on the search sphere (a crash before the padding)
    rng = np.random.default_rng(seed)
    d = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 1.0])
    d /= np.linalg.norm(d)
    runs = np.concatenate([k * 0.08 + np.arange(20) * 0.002 for k in range(12)])
    pts = rng.uniform(-0.1, 0.1, 3) + runs[:, None] * d
    g = knn_graph(pts, 5, 0.03)
    assert g.components == 12 and g.bridges == 11
    monkeypatch.setattr(graph, "_nearest_pair", nearest_pair_reference)
    ref = knn_graph(pts, 5, 0.03)
    np.testing.assert_allclose(np.sort(g.adjacency.data), np.sort(ref.adjacency.data), rtol=1e-12)
