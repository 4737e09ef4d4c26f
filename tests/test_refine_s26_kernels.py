"""Session 26: compiled loops for Algorithm 1 step 2 and the smoothing limits, each held bit for bit to the
numpy (or k-d tree) computation it replaces, on random inputs with ties, flat and degenerate cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree


@pytest.fixture
def rng():
    return np.random.default_rng(26)


def test_shape_contexts_match_the_numpy_reference(rng):
    from arboretum_server.decompose.similarity import shape_contexts, shape_contexts_reference

    checked = 0
    for t in range(400):
        b, n = int(rng.integers(1, 4)), int(rng.integers(2, 45))
        bins = (int(rng.integers(1, 7)), int(rng.integers(1, 8)), int(rng.integers(1, 6)))
        x = rng.normal(size=(b, n, 3)) * 10.0 ** rng.uniform(-3, 1)
        if t % 3 == 0:
            x = np.cumsum(x, axis=1)
        if t % 4 == 0:
            x = np.round(x, 1)  # axis-aligned vectors, repeated distances
        got, want = shape_contexts(x, bins), shape_contexts_reference(x, bins)
        assert got.shape == want.shape and np.array_equal(got, want), (t, n, bins)
        checked += got.size
    assert checked > 100_000


@pytest.mark.parametrize("n", [2, 3, 8, 12, 24, 50, 130, 300])
def test_pairwise_sum_is_numpys(rng, n):
    from arboretum_server.decompose.similarity import _pairwise_sum

    for _ in range(20):
        a = rng.random(n * n) * 10.0 ** rng.uniform(-5, 5, n * n)
        assert _pairwise_sum(a, 0, len(a)) == a.sum()
        assert _pairwise_sum(a, 3, len(a) - 3) == a[3:].sum()


def test_resample_all_matches_resample_polyline(rng):
    from arboretum_server.decompose.similarity import resample_all, resample_all_reference

    for t in range(600):
        n = int(rng.integers(1, 40))
        polylines = []
        for _ in range(int(rng.integers(1, 5))):
            m = int(rng.integers(1, 30))
            p = rng.normal(size=(m, 3)) * 10.0 ** rng.uniform(-3, 1)
            if t % 3 == 0:
                p = np.round(p, 1)
            if t % 5 == 0 and m > 2:
                p[1] = p[0]  # a zero-length step
            if t % 7 == 0:
                p[:] = p[0]  # no length at all
            polylines.append(p)
        assert np.array_equal(resample_all(polylines, n), resample_all_reference(polylines, n)), t
    assert resample_all([], 5).shape == (0, 5, 3)


def test_merged_prefixes_flat_match_the_kd_tree_version(rng):
    from arboretum_server.decompose.merge import merged_prefixes, merged_prefixes_flat

    inner = 0
    for t in range(600):
        refs = [np.cumsum(rng.normal(size=(int(rng.integers(1, 40)), 3)) * 0.01, axis=0)
                for _ in range(int(rng.integers(1, 8)))]
        if t % 4 == 0:
            refs = [np.round(r, 2) for r in refs]
        cands = []
        for _ in range(int(rng.integers(1, 6))):
            base = refs[int(rng.integers(len(refs)))]
            m = int(rng.integers(1, 40))
            c = base[np.minimum(np.arange(m), len(base) - 1)] + rng.normal(size=(m, 3)) * 0.01 * np.linspace(0, 3, m)[:, None]
            cands.append(np.round(c, 2) if t % 4 == 0 else c)
        # every other draw: tau exactly one of the distances, so ">=" is tested on a tie
        tau = 0.02 if t % 2 else float(cKDTree(refs[0]).query(cands[0])[0][len(cands[0]) // 2])
        got = merged_prefixes_flat(cands, refs, tau)
        want = merged_prefixes(cands, [cKDTree(r.copy()) for r in refs], tau)
        assert np.array_equal(got, want), t
        inner += int(((want > 0) & (want < np.array([len(c) for c in cands])[:, None])).sum())
    assert inner > 500  # prefixes that end inside their candidate, not only 0 or all of it


def test_chi_squares_and_assignment_costs_match_one_pair_at_a_time(rng):
    from arboretum_server.decompose.similarity import (
        assignment_cost,
        assignment_costs,
        chi_square,
        chi_square_reference,
        chi_squares,
    )

    for t in range(400):
        k = int(rng.choice([1, 3, 7, 8, 9, 16, 17, 120, 127, 128, 129]))
        n1, n2, m = int(rng.integers(1, 30)), int(rng.integers(1, 30)), int(rng.integers(1, 6))
        a = rng.random((n1, k)) * (rng.random((n1, k)) < rng.uniform(0.02, 1))
        hs = rng.random((m, n2, k)) * (rng.random((m, n2, k)) < rng.uniform(0.02, 1))
        which = rng.integers(0, m, int(rng.integers(1, 5)))
        got = chi_squares(a, hs, which)
        for x, w in enumerate(which):
            assert np.array_equal(got[x], chi_square(a, hs[w])), (t, k)
            assert np.array_equal(got[x], chi_square_reference(a, hs[w])), (t, k)
        assert assignment_costs(a, hs, which) == [assignment_cost(a, hs[w]) for w in which]


def _limits_reference(segments, tree):
    from arboretum_server.decompose.smooth import LIMIT, LIMIT_MIN, LOCAL_SPACINGS

    d = tree.query(np.concatenate(segments), k=8)[0]
    return np.clip(LOCAL_SPACINGS * np.median(d, axis=1), LIMIT_MIN, LIMIT)


def test_vertex_limits_match_the_kd_tree_query(rng):
    from arboretum_server.decompose.smooth import fifth_nearest, vertex_limits

    for t in range(150):
        n = int(rng.integers(5, 3000))
        pts = rng.normal(size=(n, 3)) * 0.05 if t % 3 else rng.random((n, 3)) * 0.3
        if t % 4 == 0:
            pts = np.round(pts, 2)  # ties, points on cell faces
        if t % 5 == 0:
            pts[:, 2] *= 1e-3  # a nearly flat cloud
        tree = cKDTree(pts)
        segs = [pts[rng.integers(0, n, 20)] + rng.normal(size=(20, 3)) * 0.01, rng.normal(size=(5, 3)) * 0.5]
        q = np.concatenate(segs)
        assert np.array_equal(fifth_nearest(q, tree), tree.query(q, k=8)[0][:, 3:5]), t
        assert np.array_equal(vertex_limits(segs, tree), _limits_reference(segs, tree)), t


def test_vertex_limits_of_tiny_clouds_and_no_tree():
    from arboretum_server.decompose.smooth import LIMIT, vertex_limits

    tree = cKDTree(np.array([[0.0, 0, 0], [0.001, 0, 0], [0, 0.002, 0]]))
    segs = [np.zeros((3, 3))]
    assert np.array_equal(vertex_limits(segs, tree), _limits_reference(segs, tree))
    assert vertex_limits(segs, None) == LIMIT


def test_nearest_vertex_is_the_kd_trees_or_declines_a_tie(rng):
    from arboretum_server.decompose.merge import nearest_vertex

    answered = ties = 0
    for t in range(3000):
        ref = rng.normal(size=(int(rng.integers(1, 60)), 3)) * 0.05
        if t % 3 == 0:
            ref = np.round(ref, 2)
        if t % 5 == 0 and len(ref) > 3:
            ref[2] = ref[1]  # a repeated vertex
        q = ref[int(rng.integers(len(ref)))] + (rng.normal(size=3) * 0.01 if t % 2 else 0.0)
        got = nearest_vertex(ref, q)
        d, i = cKDTree(ref.copy()).query(q)
        if got >= 0:
            answered += 1
            assert got == i, t
        else:
            ties += 1
            d2 = ((ref - q) ** 2).sum(axis=1)
            assert (d2 == d2.min()).sum() >= 2, t  # declined only on a tie
    assert answered > 2000 and ties > 10
    assert nearest_vertex(np.zeros((0, 3)), np.zeros(3)) == -1
    assert nearest_vertex(np.array([[np.nan, 0, 0]]), np.zeros(3)) == -1


def test_drop_edges_reference_matches_one_isin_per_tetrahedron_edge(rng):
    """``tetloops.drop_edges_reference`` (what the compiled ``drop_edges`` is held to) against the code before
    session 26: one ``np.isin`` per tetrahedron edge."""
    from arboretum_server.decompose.lobes import _edge_keys
    from arboretum_server.decompose.tetloops import drop_edges_reference

    def _has_edge(tets, edges):
        keep = np.ones(len(tets), bool)
        drop_edges_reference(tets, keep, edges)
        return ~keep

    def six_isin(tets, edges):
        pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
        return np.any([np.isin(_edge_keys(tets[:, i], tets[:, j]), edges) for i, j in pairs], axis=0)

    hits = 0
    for t in range(300):
        n = int(rng.integers(5, 300))
        tets = rng.integers(0, n, (int(rng.integers(0, 2000)), 4)).astype(np.int32)
        edges = np.unique(_edge_keys(rng.integers(0, n, 40), rng.integers(0, n, 40)))[: int(rng.integers(0, 40))]
        got, want = _has_edge(tets, edges), six_isin(tets, edges)
        assert got.dtype == want.dtype and np.array_equal(got, want), t
        hits += int(got.sum())
    assert hits > 1000
