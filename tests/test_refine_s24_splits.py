"""Session 24 (helper-168): a split into 20 pieces reroutes all 20, and each paid a Dijkstra bounded by a path
through foreign zones that settled most of the graph. The reroutes of one ``make_lobes`` call now share one
full run on the graph where every zone is foreign, repaired over each lobe's own zone edges
(``graph.path_after_cut``); the cloud-centring grid query is one compiled loop (``grid._query_kernel``); a
split builds its HBL once; and ``clear._packed`` knows a lobe list whose hulls are the ones it was just asked
about. Every answer must be the one the code before gave, bit for bit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra

from arboretum_server.decompose import graph
from arboretum_server.decompose.graph import path_to, shortest_path_to


def _graph(rng: np.random.Generator, n: int, tied: bool):
    """A connected symmetric graph on ``n`` nodes: weights 1-3 (many exact ties) or uniform lengths."""
    m = 3 * n
    a, b = rng.integers(0, n, m), rng.integers(0, n, m)
    a, b = a[a != b], b[a != b]
    w = rng.integers(1, 4, len(a)) * 0.1 if tied else rng.uniform(0.001, 0.05, len(a))
    chain = np.arange(n - 1)
    a, b, w = np.r_[a, chain], np.r_[b, chain + 1], np.r_[w, np.full(n - 1, 0.2)]
    adj = coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(n, n)).tocsr()
    adj.sum_duplicates()
    return adj


def _zoned(adj: csr_matrix, zone: np.ndarray, j: int, dear: float = 1000.0, own: float = 10.0):
    """(graph with every zoned edge ``dear`` times longer, lobe ``j``'s graph with its own edges ``own`` times,
    the entries of lobe ``j``'s own edges, each entry's row): ``secondary.foreign_graph``'s weights."""
    rows = np.repeat(np.arange(adj.shape[0]), np.diff(adj.indptr))
    zr, zc = zone[rows], zone[adj.indices]
    hi = np.maximum(zr, zc)
    one = ((zr == hi) | (zr < 0)) & ((zc == hi) | (zc < 0))
    base = adj.data * np.where(hi >= 0, dear, 1.0)
    cut = np.flatnonzero(np.where(one, hi, -1) == j)
    w = base.copy()
    w[cut] = adj.data[cut] * own
    return (csr_matrix((base, adj.indices, adj.indptr), shape=adj.shape),
            csr_matrix((w, adj.indices, adj.indptr), shape=adj.shape), cut, rows)


def test_repaired_distances_are_dijkstras_bit_for_bit(rng):
    checked = 0
    for tied in (True, False):
        for _ in range(40):
            n = int(rng.integers(30, 300))
            adj = _graph(rng, n, tied)
            zone = np.where(rng.random(n) < 0.5, rng.integers(0, 4, n), -1)
            root = int(rng.integers(n))
            for j in range(4):
                base, own, cut, rows = _zoned(adj, zone, j)
                start = dijkstra(base, directed=True, indices=root)
                want = dijkstra(own, directed=True, indices=root)
                got = graph._repaired(own.indptr, own.indices, own.data, start.copy(), rows, cut)
                assert np.array_equal(got, want)  # every node, not only those near the target
                checked += 1
    assert checked == 320


def test_path_after_cut_is_shortest_path_to_node_for_node(rng):
    from arboretum_server.decompose.graph import path_after_cut

    paths = tied = 0
    for tied_weights in (True, False):
        for _ in range(60):
            n = int(rng.integers(30, 250))
            adj = _graph(rng, n, tied_weights)
            zone = np.where(rng.random(n) < 0.6, rng.integers(0, 3, n), -1)
            root = int(rng.integers(n))
            for j in range(3):
                base, own, cut, rows = _zoned(adj, zone, j)
                start = dijkstra(base, directed=True, indices=root)
                dist, pred = graph.shortest_paths(own, root)
                for target in rng.integers(0, n, 3).tolist():
                    want = path_to(shortest_path_to(own, root, target, path_to(pred, target)), target)
                    got = path_after_cut(own, rows, start, cut, root, target)
                    assert got.tolist() == want.tolist()
                    tied += not graph.path_is_unique(own, dist, path_to(pred, target))
                    paths += 1
    assert paths == 1080
    assert tied > 50  # many paths had a tie, decided by tied_path as before


def test_a_target_the_cut_edges_alone_reach():
    from arboretum_server.decompose.graph import path_after_cut

    # 0 - 1 - 2 - 3 and a long edge 0 - 3; nodes 2 and 3 in lobe 0's zone, so edges 1-2, 2-3 and 0-3 are its own
    a, b, w = np.array([0, 1, 2, 0]), np.array([1, 2, 3, 3]), np.array([1.0, 1.0, 1.0, 50.0])
    adj = coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(4, 4)).tocsr()
    base, own, cut, rows = _zoned(adj, np.array([-1, -1, 0, 0]), 0, dear=100.0, own=2.0)
    start = dijkstra(base, directed=True, indices=0)
    assert start.tolist() == [0.0, 1.0, 101.0, 201.0] and len(cut) == 6
    assert graph._repaired(own.indptr, own.indices, own.data, start.copy(), rows, cut).tolist() == [0, 1, 3, 5]
    assert path_after_cut(own, rows, start, cut, 0, 3).tolist() == [0, 1, 2, 3]
    assert path_after_cut(own, rows, start, cut, 0, 0).tolist() == [0]


def test_the_compiled_grid_query_gives_the_numpy_loops_numbers(rng):
    from arboretum_server.decompose import grid
    from arboretum_server.decompose.grid import _BIG, _OFFSETS, BoxGrid, _keys

    pts = np.cumsum(rng.normal(0, 0.01, (4000, 3)), axis=0)
    g = BoxGrid(pts, 0.02)
    q = np.r_[pts[::7] + rng.normal(0, 0.01, (572, 3)), [[1e3, 1e3, 1e3]]]
    base = np.floor((q - g.origin) / g.cell).astype(np.int64)
    count, total = np.zeros(len(q)), np.zeros((len(q), 3))
    for off in _OFFSETS:  # the loop before session 24
        k = _keys(base + off)
        i = np.clip(np.searchsorted(g.keys, k), 0, len(g.keys) - 1)
        hit = g.keys[i] == k
        count[hit] += g.counts[i[hit]]
        total[hit] += g.sums[i[hit]]
    got_count, got_total = g.query(q)
    assert np.array_equal(got_count, count) and np.array_equal(got_total, total)
    kernel_count, kernel_total = np.zeros(len(q)), np.zeros((len(q), 3))
    grid._query_kernel(g.keys, g.counts, g.sums, base, _OFFSETS, _BIG, kernel_count, kernel_total)
    assert np.array_equal(kernel_count, count) and np.array_equal(kernel_total, total)
    assert count[-1] == 0 and (count[:-1] > 0).mean() > 0.9
    assert g.query(q[:0])[0].shape == (0,)


def test_packed_keeps_its_answer_for_lobes_with_the_same_hulls(rng, monkeypatch):
    from arboretum_server.decompose import clear
    from test_refine_s14_speed import _blob_lobes

    lobes = _blob_lobes(rng, 6)
    pack, box = clear._packed(lobes)
    calls = []
    plain = clear._packed_by_hulls
    monkeypatch.setattr(clear, "_packed_by_hulls", lambda lb: calls.append(1) or plain(lb))
    moved = [replace(lb, segment=np.ones((3, 3))) for lb in lobes]  # every lobe new, every hull the same
    assert clear._packed(moved)[0] is pack and clear.boxes(moved) is box
    assert clear._packed(list(lobes))[0] is pack and calls == []  # no key of ids built
    grown = list(moved)
    grown[1] = replace(moved[1], hull_vertices=moved[1].hull_vertices * 1.5)
    assert clear._packed(grown)[0] is not pack and calls == [1]


def test_a_split_builds_its_hbl_once_and_the_same(monkeypatch):
    from arboretum_server.decompose import refine, state
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose
    from arboretum_server.decompose.toytree import toy_scan, toy_truth
    from factories import hbl_arrays

    pts, _ = toy_scan(toy_truth(), n=12000, seed=1)
    d = decompose(pts, DecomposeOptions())
    lobe = d.hbl.lobes[4].points
    built = []
    plain = refine.build_hbl
    monkeypatch.setattr(refine, "build_hbl", lambda x: built.append(1) or plain(x))
    out = refine.split_lobe(d, 4, [lobe[:2], lobe[-2:]])
    assert len(built) == 1 and len(out.lobes) == len(d.lobes) + 1
    same = replace(out, hbl=state.build_hbl(out))
    assert all(np.array_equal(a, b) for a, b in zip(hbl_arrays(out), hbl_arrays(same), strict=True))
    # every piece taken for crossing: the pieces go along the split lobe's branch, and the HBL is built after
    monkeypatch.setattr(refine, "foreign", lambda *a: True)
    monkeypatch.setattr(refine, "along", lambda *a: None)
    built.clear()
    out = refine.split_lobe(d, 4, [lobe[:2], lobe[-2:]])
    assert len(built) == 1 and out.hbl.lobes[-1].branch == len(out.hbl.branches) - 1


def test_segments_sharing_a_start_give_the_reference_answers_and_hull_tests(rng):
    """``_segments_kernel`` reuses the first sample's answer and hull tests for a segment starting where the last
    tested one did (``bent_fallback``'s vertex x waypoint pairs): the same answers and counts as sample by
    sample (a guard, not a regression: the code before tested every start again and gave the same)."""
    from arboretum_server.decompose.clear import WORK, blocked, boxes, first_clear
    from test_refine_s14_speed import _blob_lobes, _reference_blocked
    from test_refine_s23_speed import _alpha_lobes
    from test_refine_s23_speed2 import _reference_tests

    for lobes in (_blob_lobes(rng, 16), _alpha_lobes(rng)):
        starts = rng.uniform(-0.1, 1.1, (12, 3))
        ends = rng.uniform(-0.1, 1.1, (10, 3))
        a, b = np.repeat(starts, len(ends), axis=0), np.tile(ends, (len(starts), 1))
        a[50:55] = b[50:55]  # points (a == b) among them, and a start shared with a skipped far segment
        a[70:72] += 5.0
        b[70:72] += 5.0
        want = _reference_blocked(lobes, 1, a, b, 0.02, boxes(lobes))
        WORK["hull_tests"] = 0
        got = blocked(lobes, 1, a, b, 0.02, boxes(lobes))
        assert np.array_equal(got, want) and 0 < want.sum() < len(a)
        assert WORK["hull_tests"] == _reference_tests(lobes, 1, a, b, 0.02) > 0
        assert first_clear(lobes, 1, a, b, 0.02, boxes(lobes)) == int(np.argmin(want))
