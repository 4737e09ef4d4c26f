"""Splits, session 29: every path read from a predecessor tree in one compiled call (``graph.paths_to``), the lobes'
hull pack spliced from the last one when a few hulls changed (``hullpack.splice_packs``, ``clear._joined``) and
``carve_route``'s blockers cut from one joined pool (``tunnel._others_pool``). Each gives the arrays of before."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from test_refine_s23_speed import _alpha_lobes


def _tree(rng, n):
    """A random predecessor tree (N,) int32 over ``n`` nodes: -1 at roots (some nodes unreachable)."""
    pred = np.full(n, -1, np.int32)
    order = rng.permutation(n)
    for i in range(1, n):
        if rng.random() < 0.95:
            pred[order[i]] = order[rng.integers(0, i)]
    return pred


def test_paths_to_walks_every_path_as_path_to_does(rng):
    from arboretum_server.decompose.graph import path_to, paths_to

    for _ in range(200):
        n = int(rng.integers(1, 300))
        pred = _tree(rng, n)
        nodes = rng.integers(0, n, int(rng.integers(0, 25))).tolist()
        for p in (pred, pred.astype(np.int64)):
            got, want = paths_to(p, nodes), [path_to(pred.tolist(), k) for k in nodes]
            assert len(got) == len(want)
            for g, w in zip(got, want):
                assert g.dtype == np.int64 and g.tolist() == w.tolist()


def test_paths_to_leaves_bad_trees_and_nodes_to_path_to():
    import pytest

    from arboretum_server.decompose.graph import paths_to

    assert [p.tolist() for p in paths_to([-1, 0, 1], [2, 0])] == [[0, 1, 2], [0]]  # a list: path_to's way
    with pytest.raises(IndexError):
        paths_to(np.array([-1, 0], np.int32), [5])  # path_to's IndexError, no read outside the array
    with pytest.raises(IndexError):
        paths_to(np.array([-1, 7], np.int32), [1])  # a predecessor outside the tree


def _packs(rng, n):
    from arboretum_server.decompose.hullpack import pack_hull

    out = [pack_hull(lb.hull_vertices, lb.hull_faces) for lb in _alpha_lobes(rng, n)]
    return out + [pack_hull(np.zeros((0, 3)), np.zeros((0, 3), np.int64))]  # a hull of no face


def test_splice_packs_equals_join_packs(rng):
    from arboretum_server.decompose.hullpack import join_packs, splice_packs, vertex_first

    hulls = _packs(rng, 8)
    for _ in range(150):
        n = int(rng.integers(1, 14))
        old = [hulls[i] for i in rng.integers(0, len(hulls), n)]
        swap = rng.choice(n, int(rng.integers(0, n + 1)), replace=False)
        new = {int(i): hulls[int(rng.integers(0, len(hulls)))] for i in swap}
        got = splice_packs(join_packs(old), vertex_first(old), new)
        want = join_packs([new.get(i, p) for i, p in enumerate(old)])
        for name, g, w in zip(want._fields, got, want):
            assert g.dtype == w.dtype and g.shape == w.shape and np.array_equal(g, w), name


def test_packed_after_a_few_hulls_change_equals_a_fresh_join(rng):
    from arboretum_server.decompose import clear
    from arboretum_server.decompose.hullpack import join_packs, pack_hull

    lobes = _alpha_lobes(rng, 9)
    spare = _alpha_lobes(rng, 4)
    clear._packed(lobes)
    for t in range(12):
        k = int(rng.integers(0, len(lobes)))
        s = spare[t % len(spare)]
        lobes[k] = replace(lobes[k], hull_vertices=s.hull_vertices.copy(), hull_faces=s.hull_faces.copy())
        pack, (lo, hi) = clear._packed(list(lobes))
        want = join_packs([pack_hull(lb.hull_vertices, lb.hull_faces) for lb in lobes])
        for name, g, w in zip(want._fields, pack, want):
            assert g.dtype == w.dtype and np.array_equal(g, w), name
        assert np.array_equal(lo, [lb.hull_vertices.min(axis=0) for lb in lobes])
        assert np.array_equal(hi, [lb.hull_vertices.max(axis=0) for lb in lobes])


def test_others_pool_gives_the_blockers_joined_for_each_lobe(rng):
    from arboretum_server.decompose.merge import resample_step
    from arboretum_server.decompose.tunnel import _others_pool

    lobes = [replace(lb, segment=rng.uniform(0, 1, (int(rng.integers(2, 6)), 3))) for lb in _alpha_lobes(rng, 6)]
    wood = rng.uniform(0, 1, (7, 3))
    j = 2
    pool, owner, any_branch = _others_pool(lobes, {j}, wood, 0.01)
    assert any_branch
    for k in range(len(lobes)):
        if k == j:
            continue
        want = np.concatenate([wood, *[resample_step(lobes[i].segment, 0.01) for i in range(len(lobes))
                                       if i not in (j, k)]])
        got = pool[owner != k]
        assert got.shape == want.shape and np.array_equal(got, want)
    two = lobes[:2]
    assert not _others_pool(two, {0, 1}, wood, 0.01)[2]  # no other branch: ``wood`` alone


def test_pinched_edges_equal_the_numpy_reference(rng):
    from arboretum_server.decompose.lobes import _pinched_edges, _pinched_edges_reference

    for _ in range(300):
        n = int(rng.integers(3, 30))
        faces = rng.integers(0, n, (int(rng.integers(0, 60)), 3)).astype(np.int32)
        faces = np.concatenate([faces, faces[: int(rng.integers(0, len(faces) + 1))]])  # edges shared 2-4 times
        got, want = _pinched_edges(faces), _pinched_edges_reference(faces)
        assert got.dtype == want.dtype == np.int64 and got.tolist() == want.tolist()


def test_lobes_entered_and_carve_route_boxes_skip_only_lobes_no_point_enters(rng):
    from arboretum_server.decompose.clear import boxes
    from arboretum_server.decompose.tunnel import _boxes_meet, enters, lobes_entered

    lobes = _alpha_lobes(rng, 7)
    lo, hi = boxes(lobes)
    for t in range(40):
        woods = [rng.uniform(-0.1, 0.45, (int(rng.integers(1, 30)), 3)) * rng.uniform(0.2, 1.0)
                 for _ in range(int(rng.integers(1, 5)))]
        if t % 5 == 0:
            woods[0][0] = np.nan  # a nan point lies in no box: the others still count
        want = [sum(enters(lobes[k], w) for k in range(len(lobes))) for w in woods]
        assert lobes_entered(lobes, list(range(len(lobes))), woods).tolist() == want
        for w in woods:
            meets = _boxes_meet(lo, hi, w)
            for k in range(len(lobes)):
                near = ((w > lo[k]) & (w < hi[k])).all(axis=1).any()
                assert meets[k] or not near


def test_compact_equals_the_numpy_reference(rng):
    from arboretum_server.decompose.lobes import _compact, _compact_reference

    for _ in range(300):
        n = int(rng.integers(1, 40))
        pts = rng.normal(size=(n, 3))
        faces = rng.integers(0, n, (int(rng.integers(0, 50)), 3)).astype(np.int32)
        (gv, gf), (wv, wf) = _compact(pts, faces), _compact_reference(pts, faces)
        assert gv.dtype == wv.dtype and gv.shape == wv.shape and np.array_equal(gv, wv)
        assert gf.dtype == wf.dtype == np.int32 and gf.shape == wf.shape and np.array_equal(gf, wf)
    pts = rng.normal(size=(5, 3))
    faces = np.array([[0, 1, -1]], np.int32)  # an index numpy wraps: left to numpy, as before
    assert all(np.array_equal(g, w) for g, w in zip(_compact(pts, faces), _compact_reference(pts, faces)))
