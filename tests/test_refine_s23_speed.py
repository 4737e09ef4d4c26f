"""Splits into many pieces (session 23): the packed inside tests read each hull's faces through an XY grid
(``hullpack._grid_of``, ``_bucket``) and give, bit for bit, the answers of testing every face (``lobes.inside``), for
a fraction of the face tests."""

from __future__ import annotations

import numpy as np

from test_refine_s14_speed import _blob_lobes, _reference_blocked, _reference_inside_foreign


def _alpha_lobes(rng, n=6):
    """``n`` lobes with the alpha shapes of 400 random points each (hundreds of small faces, concave)."""
    from arboretum_server.decompose.lobes import plain_hull
    from arboretum_server.decompose.state import LobeState

    out = []
    for _ in range(n):
        c = rng.uniform(0, 0.3, 3)
        verts, faces, alpha, steps, _ = plain_hull(c + rng.normal(0, 0.05, (400, 3)), 0.04)
        out.append(LobeState(np.arange(3), c, verts, faces, alpha, np.zeros((2, 3)), 0, 0, steps))
    return out


def test_every_face_whose_box_holds_a_point_is_in_the_points_cell(rng):
    from arboretum_server.decompose.hullpack import _cell, pack_hull

    lb = _alpha_lobes(rng, 1)[0]
    pack = pack_hull(lb.hull_vertices, lb.hull_faces)
    nx, ny = int(pack.grid[0, 4]), int(pack.grid[0, 5])
    assert len(pack.faces) > 200 and nx * ny == len(pack.cell_start) - 1 > 50
    corners = np.concatenate([pack.face_lo, pack.face_hi, pack.face_lo * [1, 0] + pack.face_hi * [0, 1]])
    q = np.concatenate([corners, rng.uniform(pack.face_lo.min(axis=0), pack.face_hi.max(axis=0), (3000, 2))])
    for x, y in q:
        cell = _cell(pack.grid, 0, x, 0) * ny + _cell(pack.grid, 0, y, 1)
        held = set(pack.cell_faces[pack.cell_start[cell]:pack.cell_start[cell + 1]].tolist())
        need = np.flatnonzero((pack.face_lo[:, 0] <= x) & (x <= pack.face_hi[:, 0])
                              & (pack.face_lo[:, 1] <= y) & (y <= pack.face_hi[:, 1]))
        assert set(need.tolist()) <= held
    assert len(pack.cell_faces) / (nx * ny) < len(pack.faces) / 10  # a point's cell holds few of the faces


def test_gridded_inside_tests_match_every_face_tested(rng):
    from arboretum_server.decompose.clear import blocked, boxes, inside_foreign

    for lobes in (_alpha_lobes(rng), _blob_lobes(rng)):
        lo, hi = boxes(lobes)
        q = rng.uniform(lo.min(axis=0), hi.max(axis=0), (6000, 3))
        on = np.concatenate([lb.hull_vertices for lb in lobes])[:600]
        q[:len(on)] = on  # on the hulls themselves
        for j in (0, 3):
            want = _reference_inside_foreign(lobes, j, q)
            assert np.array_equal(inside_foreign(lobes, j, q), want) and 0 < want.sum() < len(q)
        a, b = q[:300], q[-300:]
        want = _reference_blocked(lobes, 1, a, b, 0.005, boxes(lobes))
        assert np.array_equal(blocked(lobes, 1, a, b, 0.005, boxes(lobes)), want) and 0 < want.sum() < 300


def test_flat_and_empty_hulls_get_a_one_cell_grid():
    from arboretum_server.decompose.hullpack import inside_any, join_packs, pack_hull

    flat = pack_hull(np.array([[0.0, 0, 0], [0, 0, 1], [0, 0, 2]]), np.array([[0, 1, 2], [0, 2, 1]]))
    assert flat.grid[0, 2:].tolist() == [0.0, 0.0, 1.0, 1.0] and flat.cell_faces.tolist() == [0, 1]
    empty = pack_hull(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    both = join_packs([flat, empty, flat])
    assert both.cell_first.tolist() == [0, 1, 2, 3] and both.cell_start.tolist() == [0, 2, 2, 4]
    assert both.cell_faces.tolist() == [0, 1, 2, 3]
    lo, hi = np.full((3, 3), -1.0), np.full((3, 3), 3.0)
    out, tests = inside_any(both, lo, hi, -1, np.array([[0.0, 0, 0.5]]))
    assert not out[0] and tests == 3  # every box holds the point; no hull does
    none = join_packs([])
    assert inside_any(none, np.zeros((0, 3)), np.zeros((0, 3)), -1, np.zeros((2, 3)))[0].tolist() == [False, False]


def _mains_through(rng, n=5):
    """A BranchSet of ``n`` random polylines of 30 vertices through the 1 m cube (main branches)."""
    from arboretum_server.decompose.merge import BranchSet, add_branch

    mains = BranchSet()
    for b in range(n):
        seg = np.cumsum(rng.normal(0, 0.04, (30, 3)), axis=0) + rng.uniform(0, 1, 3)
        add_branch(mains, seg, -1 if b == 0 else 0, -1 if b == 0 else 0)
    return mains


def _reference_straight(lobes, j, centre, mains, tries=64, step=0.005, batch=8):
    """``straight_fallback`` before session 23: a ``blocked`` call per ``batch`` vertices."""
    from arboretum_server.decompose.clear import (
        _nearest_vertices,
        _straight,
        blocked,
        boxes,
        main_vertices,
    )

    verts, owner = main_vertices(mains)
    order = _nearest_vertices(verts, centre, tries)
    for start in range(0, len(order), batch):
        cand = order[start:start + batch]
        bad = blocked(lobes, j, verts[cand], np.broadcast_to(centre, (len(cand), 3)), step, boxes(lobes))
        if not bad.all():
            i = int(cand[int(np.argmin(bad))])
            return _straight(verts[i], centre, owner[i])
    return None


def test_first_clear_calls_give_the_straight_branches_of_the_batched_loops(rng):
    from arboretum_server.decompose.clear import WORK, blocked, boxes, first_clear, straight_from

    lobes = _blob_lobes(rng, 16)
    mains = _mains_through(rng)
    centres = rng.uniform(0, 1, (40, 3))
    want = [_reference_straight(lobes, 2, c, mains) for c in centres]
    assert 5 < sum(w is None for w in want) < 35  # some reached, some not
    first = next(i for i, w in enumerate(want) if w is not None)
    k, got = straight_from(lobes, 2, centres, mains)
    assert k == first and np.array_equal(got[0], want[first][0]) and got[1:] == want[first][1:]
    for i in range(len(centres)):
        found = straight_from(lobes, 2, centres[i:i + 1], mains)
        assert (found is None) == (want[i] is None)
        assert found is None or (np.array_equal(found[1][0], want[i][0]) and found[1][1:] == want[i][1:])
    a, b = rng.uniform(0, 1, (300, 3)), rng.uniform(0, 1, (300, 3))
    WORK["hull_tests"] = 0
    bad = blocked(lobes, 0, a, b, 0.005, boxes(lobes))
    every, WORK["hull_tests"] = WORK["hull_tests"], 0
    assert first_clear(lobes, 0, a, b, 0.005, boxes(lobes)) == int(np.argmin(bad)) and not bad.all()
    assert 0 < WORK["hull_tests"] < every  # the segments after the first clear one are not tried
    assert first_clear(lobes, 0, a[bad], b[bad], 0.005, boxes(lobes)) == -1
    assert first_clear(lobes, 0, a[:0], b[:0], 0.005, boxes(lobes)) == -1
