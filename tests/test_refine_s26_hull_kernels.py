"""Session 26 (helper-187): an insert's alpha shapes and reroutes, cheaper with the same answers bit for bit.
``Tetrahedra.shape`` counts covered points, orients the boundary faces and drops pinched tetrahedra in compiled
loops (``tetloops.covered``, ``orient``, ``drop_edges``) and renumbers the faces without a sort
(``lobes._compact``); the repair of a reroute's distances stops once the heap passes the target's distance
(``graph._repaired_to``); a rerouted lobe's own zone edges are found once (``secondary._own_entries``). Each is
held here against the code before it."""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import Delaunay

from arboretum_server.decompose import graph, lobes, tetloops


def _clouds(rng: np.random.Generator):
    """Random clouds and grid clouds (many cospherical and coplanar corners: exact zeros in the orientation)."""
    for _ in range(12):
        yield rng.random((int(rng.integers(8, 300)), 3))
    for _ in range(6):
        g = np.stack(np.meshgrid(*[np.arange(int(rng.integers(3, 7)))] * 3), -1).reshape(-1, 3) * 0.01
        yield g + rng.integers(0, 2, g.shape) * 1e-3


def test_covered_orient_and_drop_edges_match_the_numpy_code(rng):
    faces_seen = flipped = dropped = 0
    for pts in _clouds(rng):
        dt = Delaunay(pts)
        tets, nb = dt.simplices, dt.neighbors
        for frac in (0.3, 0.7, 1.0):
            keep = rng.random(len(tets)) < frac
            assert tetloops.covered(tets, keep, len(pts)) == tetloops.covered_reference(tets, keep, len(pts))
            faces, opp = tetloops.boundary(tets, nb, keep)
            got, want = tetloops.orient(pts, faces, opp), tetloops.orient_reference(pts, faces, opp)
            assert got.dtype == want.dtype and np.array_equal(got, want)
            faces_seen += len(faces)
            flipped += int((got != faces).any(axis=1).sum())
            edges = np.unique(lobes._edge_keys(faces[:, 0], faces[:, 1]))[:: int(rng.integers(2, 6))]
            a, b = keep.copy(), keep.copy()
            tetloops.drop_edges(tets, a, edges)
            tetloops.drop_edges_reference(tets, b, edges)
            assert np.array_equal(a, b)
            dropped += int((keep & ~a).sum())
    assert faces_seen > 10_000 and flipped > 1_000 and dropped > 1_000


def test_compact_is_np_unique(rng):
    for _ in range(50):
        n = int(rng.integers(4, 200))
        pts = rng.random((n, 3))
        faces = rng.integers(0, n, (int(rng.integers(1, 300)), 3)).astype(np.int32)
        used, inv = np.unique(faces, return_inverse=True)
        v, f = lobes._compact(pts, faces)
        assert np.array_equal(v, pts[used]) and f.dtype == np.int32
        assert np.array_equal(f, inv.reshape(-1, 3).astype(np.int32))


def test_shapes_of_a_cloud_match_the_code_before(rng):
    """Plain and carved shapes at every probe radius: the new ``shape`` against the numpy steps it replaced."""

    def old_shape(tet: lobes.Tetrahedra, radius: float):
        keep = lobes._walled_in(tet.neighbours, tet.flat, tet.radii < radius)
        if not keep.any():
            return None
        faces, opp = tetloops.boundary(tet.tets, tet.neighbours, keep)
        for _ in range(lobes.PINCH_ROUNDS if tet.carve else 0):
            pinched = lobes._pinched_edges(faces)
            if not len(pinched):
                break
            kept = tet.tets[keep]
            keep[keep] = ~np.any([np.isin(lobes._edge_keys(kept[:, i], kept[:, j]), pinched)
                                  for i, j in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]], axis=0)
            if not keep.any():
                break
            faces, opp = tetloops.boundary(tet.tets, tet.neighbours, keep)
        used = np.zeros(len(tet.points), bool)
        used[tet.tets[keep].ravel()] = True
        if not keep.any() or used.sum() < lobes.MIN_COVER * tet.n_own:
            return None
        faces = tetloops.orient_reference(tet.points, faces, opp)
        u, inv = np.unique(faces, return_inverse=True)
        return tet.points[u].copy(), inv.reshape(-1, 3).astype(np.int32)

    shapes = 0
    for pts in _clouds(rng):
        plain = lobes.Tetrahedra(pts)
        carved = plain.without(pts[rng.integers(0, len(pts), 3)] + 0.01 * rng.standard_normal((3, 3)))
        for tet in (plain, carved):
            for radius in (0.05, 0.1, 0.2, 0.4, 1.0):
                got, want = tet.shape(radius), old_shape(tet, radius)
                assert (got is None) == (want is None)
                if got is not None:
                    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
                    shapes += 1
    assert shapes > 60


def test_repair_stopped_at_the_target_agrees_at_and_below_it(rng):
    """Every node at or below the target's repaired distance holds Dijkstra's distance bit for bit, every other
    node stays above it, and the repair did stop early (some node above keeps a value above Dijkstra's)."""
    from test_refine_s24_splits import _graph, _zoned

    stopped = checked = 0
    for tied in (True, False):
        for _ in range(30):
            n = int(rng.integers(30, 300))
            adj = _graph(rng, n, tied)
            zone = np.where(rng.random(n) < 0.5, rng.integers(0, 4, n), -1)
            root = int(rng.integers(n))
            for j in range(4):
                base, own, cut, rows = _zoned(adj, zone, j)
                start = dijkstra(base, directed=True, indices=root)
                want = dijkstra(own, directed=True, indices=root)
                for target in rng.integers(0, n, 3).tolist():
                    got = graph._repaired_to(own.indptr, own.indices, own.data, start.copy(), rows, cut, target)
                    low = want <= want[target]
                    assert got[target] == want[target]
                    assert np.array_equal(got[low], want[low]) and (got[~low] > want[target]).all()
                    stopped += bool((got > want).any())
                    checked += 1
    assert checked == 720 and stopped > 100


def test_own_entries_are_the_lobes_zone_edges(rng):
    from arboretum_server.decompose import secondary as s
    from test_refine_s24_splits import _graph

    adj = _graph(rng, 200, False)
    zone = np.where(rng.random(200) < 0.6, rng.integers(0, 5, 200), -1).astype(np.int32)
    r = s._Route(None, adj, 0, zone, None, None, 0.0, None, None, None, {}, None)
    r.cache["edges"] = s._edge_zones(adj, zone)
    for j in (3, 0, 4, 3, 7):
        assert np.array_equal(s._own_entries(r, j), np.flatnonzero(r.cache["edges"][2] == j))
    assert sorted(r.cache["owned"]) == [0, 3, 4, 7]
