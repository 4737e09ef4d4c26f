"""``decompose --points 0`` leaner (session 14, helper-112): the box-counting dimension counted once per
occupied cell, the kNN graph's neighbours kept as int32 and queried in chunks, bridging candidates found
without (N k,) index copies, and a lonely component's KD-tree asked only about outsiders that can beat
the bound. Each gives the same numbers as the code before it (written here as the reference)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

from arboretum_server.decompose import graph, separate
from arboretum_server.decompose.grid import BoxGrid, box_counts


def _clouds(rng):
    """A random blob, the same quantised to 1 mm (points on cell borders, tied distances), a thin line."""
    blob = rng.normal(0, 0.05, (6000, 3))
    line = np.c_[np.linspace(0, 0.8, 3000), np.zeros(3000), rng.normal(0, 0.001, 3000)]
    return [blob, np.round(blob, 3), line]


@pytest.mark.parametrize("cell", [separate.CELL, 3 * separate.CELL, 0.001])
def test_box_counts_are_the_grids_counts_at_its_own_points(rng, cell):
    for pts in _clouds(rng):
        np.testing.assert_array_equal(box_counts(pts, cell), BoxGrid(pts, cell).query(pts)[0])


def _local_dimension_before(points, neighbours):
    """``separate.local_dimension`` before session 14: a grid query per point, one (N, k + 1) gather."""
    n1, _ = BoxGrid(points, separate.CELL).query(points)
    n2, _ = BoxGrid(points, 3 * separate.CELL).query(points)
    d = np.log(n2 / np.maximum(n1, 1)) / np.log(3.0)
    nb = np.concatenate([np.arange(len(points))[:, None], neighbours], axis=1)
    return d[nb].mean(axis=1)


def test_local_dimension_is_bit_identical_without_a_grid_query_per_point(rng, monkeypatch):
    pts = np.round(rng.normal(0, 0.05, (20_000, 3)), 3)
    nb = cKDTree(pts).query(pts, k=17)[1][:, 1:]
    want = _local_dimension_before(pts, nb)

    def refuse(self, q):
        raise AssertionError("a per-point grid query")

    monkeypatch.setattr(separate, "CHUNK", 4096)  # several chunks, the last one short
    monkeypatch.setattr(BoxGrid, "query", refuse)
    np.testing.assert_array_equal(separate.local_dimension(pts, nb.astype(np.int32)), want)


def test_the_graph_keeps_int32_neighbours_and_its_kd_tree(rng):
    pts = rng.normal(0, 0.05, (5000, 3))
    g = graph.knn_graph(pts, 5, 0.05)
    assert g.neighbours.dtype == np.int32 and g.neighbours.shape == (5000, graph.CANDIDATES)
    np.testing.assert_array_equal(g.neighbours, cKDTree(pts).query(pts, k=graph.CANDIDATES + 1)[1][:, 1:])
    assert isinstance(g.tree, cKDTree) and g.tree.n == 5000
    np.testing.assert_array_equal(g.tree.data, pts)


def _knn_graph_before(points, k, radius):
    """``graph.knn_graph`` before session 14 (one query, (N k,) index arrays; ``_nearest_pair`` shared)."""
    n = len(points)
    tree = cKDTree(points)
    dist, nb = tree.query(points, k=min(n, max(k, graph.CANDIDATES) + 1))
    rows = np.repeat(np.arange(n), k)
    d, c = dist[:, 1 : k + 1].ravel(), nb[:, 1 : k + 1].ravel()
    ok = d <= radius
    adj = graph._edges(rows[ok], c[ok], np.maximum(d[ok], 1e-12), n)
    ncomp, lab = connected_components(adj, directed=False)
    if ncomp == 1:
        return adj
    dist, nb = dist[:, 1:], nb[:, 1:]
    a_all, b_all, w_all = [], [], []
    while True:
        src = np.repeat(np.arange(n), nb.shape[1])
        dst, w = nb.ravel(), dist.ravel()
        cross = lab[src] != lab[dst]
        ca, cb, cw = graph._isolated_edges(points, tree, lab, ncomp, src[cross], dst[cross], w[cross])
        la, lb = lab[ca], lab[cb]
        order = np.lexsort((cw, np.minimum(la, lb), np.maximum(la, lb)))
        key = np.minimum(la, lb)[order] * ncomp + np.maximum(la, lb)[order]
        first = order[np.r_[True, key[1:] != key[:-1]]]
        comp = coo_matrix((cw[first] + 1e-12, (la[first], lb[first])), shape=(ncomp, ncomp))
        mst = minimum_spanning_tree(comp).tocoo()
        pick = {(min(i, j), max(i, j)) for i, j in zip(mst.row, mst.col)}
        sel = [e for e in first if (min(lab[ca[e]], lab[cb[e]]), max(lab[ca[e]], lab[cb[e]])) in pick]
        a_all.append(ca[sel])
        b_all.append(cb[sel])
        w_all.append(cw[sel])
        merged = coo_matrix((np.ones(len(sel)), (lab[ca[sel]], lab[cb[sel]])), shape=(ncomp, ncomp))
        n2, clab = connected_components(merged, directed=False)
        if n2 == 1:
            break
        lab, ncomp = clab[lab], n2
    a, b, w = np.concatenate(a_all), np.concatenate(b_all), np.concatenate(w_all)
    return (adj + graph._edges(a, b, np.maximum(w, 1e-12), n)).tocsr()


def _blobs(rng, quantum=0.0):
    """120 blobs of 30-300 points scattered in a 0.6 m box: components, some lonely, bridged in rounds."""
    centres = rng.uniform(0, 0.6, (120, 3))
    pts = np.vstack([c + rng.normal(0, 0.004, (int(rng.integers(30, 300)), 3)) for c in centres])
    return np.unique(np.round(pts, 3), axis=0) if quantum else pts


@pytest.mark.parametrize("quantum", [0.0, 0.001])
def test_the_graph_is_bit_identical_to_the_one_before(rng, quantum, monkeypatch):
    pts = _blobs(rng, quantum)
    monkeypatch.setattr(graph, "QUERY_CHUNK", 1000)  # several chunks
    g = graph.knn_graph(pts, 5, 0.05)
    ref = _knn_graph_before(pts, 5, 0.05)
    assert g.components > 50 and g.bridges == g.components - 1
    for name in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(g.adjacency, name), getattr(ref, name))


def _nearest_pair_before(points, tree, inside, lab, c):
    """``graph._nearest_pair`` before session 14: every outsider in the bounding ball asked."""
    own = points[inside]
    ends = np.unique(np.r_[own.argmin(axis=0), own.argmax(axis=0)])
    d, j = tree.query(own[ends], k=min(len(points), len(inside) + 1))
    d = np.where(lab[j] != c, d, np.inf)
    first = np.unravel_index(int(np.argmin(d)), d.shape)
    bound, witness = float(d[first]), j[first]
    lo, hi = own.min(axis=0), own.max(axis=0)
    reach = float(np.linalg.norm(hi - lo)) / 2 + bound
    pad = 1e-9 * max(reach, float(np.abs(own).max()))
    near = np.asarray(tree.query_ball_point((lo + hi) / 2, reach + pad), np.int64)
    near = np.union1d(near[lab[near] != c], [witness])
    d, k = cKDTree(own).query(points[near])
    r = int(np.argmin(d))
    return inside[k[r : r + 1]], near[r : r + 1], d[r : r + 1]


class _Counting(cKDTree):
    asked = 0

    def query(self, x, *args, **kwargs):
        _Counting.asked += len(np.atleast_2d(x))
        return super().query(x, *args, **kwargs)


def test_a_long_components_tree_is_asked_only_about_outsiders_that_can_win(rng, monkeypatch):
    # a 1 m rod beside a dense crowd of other points: its bounding ball holds the crowd, but only the
    # outsiders within the bound of its box can be nearer, and the answer is the old one exactly
    rod = np.c_[np.linspace(0, 1, 400), np.zeros(400), np.zeros(400)]
    crowd = rng.uniform([0, 0.05, -0.3], [1, 0.4, 0.3], (20_000, 3))
    for pts in (np.vstack([rod, crowd]), np.round(np.vstack([rod, crowd]), 2)):
        lab = np.r_[np.zeros(400, int), np.ones(len(crowd), int)]
        tree = cKDTree(pts)
        inside = np.arange(400)
        want = _nearest_pair_before(pts, tree, inside, lab, 0)
        monkeypatch.setattr(graph, "cKDTree", _Counting)
        _Counting.asked = 0
        got = graph._nearest_pair(pts, tree, inside, lab, 0)
        monkeypatch.undo()
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)
        assert _Counting.asked < 0.05 * len(crowd)  # before: every crowd point in the ball (> 10,000)


def _peak(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_building_the_graph_holds_less_than_a_k_column_int64_copy_per_point(rng):
    # before: the (N, 17) int64 and float64 answers, (N 16,) int64 candidate indices and their copies:
    # 1,195 bytes a point on this cloud; now about 645
    pts = _blobs(rng)
    per_point = _peak(lambda: graph.knn_graph(pts, 5, 0.05)) / len(pts)
    assert per_point < 850
