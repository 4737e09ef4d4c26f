"""Splits into many pieces, second pass (session 23): a sampled segment tries only the hulls whose box meets
its own (``hullpack._hulls_near``), a hull's pack is built in one compiled call (``_face_boxes``,
``_grid_of``), ``clear._packed`` knows the lobes it was just asked about, and ``bent_fallback`` tests main
vertices only until it has its ``tries`` starts (``clear._outside_first``). Every answer, and every count of
hull tests, is the one of before."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from test_refine_s14_speed import _blob_lobes, _reference_blocked
from test_refine_s23_speed import _alpha_lobes


def _segments(rng, n=120):
    """Random segments through the 1 m cube, with a point (a == b), axis-parallel ones and far ones."""
    a, b = rng.uniform(-0.1, 1.1, (n, 3)), rng.uniform(-0.1, 1.1, (n, 3))
    b[:10] = a[:10]
    b[10:20, 1:] = a[10:20, 1:]
    a[20:25] += 5.0
    b[20:25] += 5.0
    return a, b


def _reference_tests(lobes, j, a, b, step, stride=4):
    """The hull tests the kernel made before session 23: for each segment, its samples every ``stride``-th
    first, then the rest, up to the first inside a foreign hull; for each sample every hull but ``j``
    whose box strictly holds it, in order, up to the first holding it."""
    from arboretum_server.decompose.clear import _sample_counts, boxes
    from arboretum_server.decompose.lobes import inside

    lo, hi = boxes(lobes)
    tests = 0
    for s, c in enumerate(_sample_counts(a, b, step)):
        order = [i for i in range(c) if i % stride == 0] + [i for i in range(c) if i % stride]
        t = np.linspace(0.0, 1.0, c)
        for i in order:
            q = a[s] + t[i] * (b[s] - a[s])
            hit = False
            for k in range(len(lobes)):
                if k != j and (lo[k] < q).all() and (q < hi[k]).all():
                    tests += 1
                    if inside(lobes[k].hull_vertices, lobes[k].hull_faces, q[None])[0]:
                        hit = True
                        break
            if hit:
                break
    return tests


def test_a_segment_tries_every_hull_whose_box_a_sample_enters(rng):
    from arboretum_server.decompose.clear import _segment_samples, boxes
    from arboretum_server.decompose.hullpack import _hulls_near

    lobes = _blob_lobes(rng, 16)
    lo, hi = boxes(lobes)
    a, b = _segments(rng)
    q, which = _segment_samples(a, b, 0.005)
    near = np.zeros(len(lobes), np.int64)
    for s in range(len(a)):
        got = near[:_hulls_near(lo, hi, 3, a[s], b[s], near)].tolist()
        sl, sh = np.minimum(a[s], b[s]), np.maximum(a[s], b[s])
        meets = ((lo < sh + 1e-6) & (hi > sl - 1e-6)).all(axis=1)
        assert got == [k for k in np.flatnonzero(meets).tolist() if k != 3]  # ascending, skip left out
        held = ((q[which == s, None] > lo) & (q[which == s, None] < hi)).all(axis=2).any(axis=0)
        held[3] = False
        assert set(np.flatnonzero(held).tolist()) <= set(got)
    assert _hulls_near(lo, hi, -1, a[20], b[20], near) == 0  # 5 m away: no hull at all


def test_segments_give_the_same_answers_and_hull_tests(rng):
    from arboretum_server.decompose.clear import WORK, blocked, boxes, first_clear

    for lobes in (_blob_lobes(rng, 16), _alpha_lobes(rng)):
        a, b = _segments(rng, 80)
        want = _reference_blocked(lobes, 1, a, b, 0.02, boxes(lobes))
        WORK["hull_tests"] = 0
        got = blocked(lobes, 1, a, b, 0.02, boxes(lobes))
        assert np.array_equal(got, want) and 0 < want.sum() < 70 and not want[20:25].any()
        assert WORK["hull_tests"] == _reference_tests(lobes, 1, a, b, 0.02) > 0
        assert first_clear(lobes, 1, a, b, 0.02, boxes(lobes)) == int(np.argmin(want))


def _numpy_grid(verts, flo, fhi):
    """The grid, cell starts and cell faces as ``hullpack`` built them in numpy before helper-165."""
    from arboretum_server.decompose.hullpack import FACES_PER_CELL, GRID_MAX, _bucket

    lo, span = verts[:, :2].min(axis=0), np.ptp(verts[:, :2], axis=0)
    n = int(np.clip(np.sqrt(len(flo) / FACES_PER_CELL), 1, GRID_MAX))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        per = n / span
    per = np.where(np.isfinite(per) & (span > 0), per, 0.0)
    grid = np.array([lo[0], lo[1], per[0], per[1], n, n], np.float64)
    return (grid, *_bucket(grid, flo, fhi))


def test_the_compiled_pack_holds_the_numbers_numpy_gave(rng):
    from arboretum_server.decompose.hullpack import _face_boxes, _grid_of, pack_hull

    hulls = [(lb.hull_vertices, lb.hull_faces) for lb in _alpha_lobes(rng, 3) + _blob_lobes(rng, 3)]
    hulls += [(np.array([[0.0, 0, 0], [0, 0, 1], [0, 0, 2]]), np.array([[0, 1, 2], [0, 2, 1]])),  # flat
              (np.array([[1e-310, 0, 0], [0, 1e-310, 1], [0, 0, 2]]), np.array([[0, 1, 2], [0, 2, 1]])),  # tiny
              (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [9, 9, 9]]), np.array([[0, 1, 2], [0, 2, 1]]))]
    for verts, faces in hulls:
        pack = pack_hull(verts, faces)
        corner = verts[faces]
        flo, fhi = corner[:, :, :2].min(axis=1), corner[:, :, :2].max(axis=1)
        grid, start, cells = _numpy_grid(verts, flo, fhi)  # the numpy build of before
        assert np.array_equal(pack.face_lo, flo) and np.array_equal(pack.face_hi, fhi)
        assert np.array_equal(pack.face_top, corner[:, :, 2].max(axis=1))
        assert np.array_equal(pack.grid[0], grid) and pack.grid.dtype == grid.dtype
        assert np.array_equal(pack.cell_start, start) and np.array_equal(pack.cell_faces, cells)
        assert np.array_equal(_face_boxes(verts, faces)[2], pack.face_top)
        assert np.array_equal(_grid_of(verts, len(faces), 2.0, 64), grid)
    big = hulls[0]
    assert _grid_of(big[0], len(big[1]), 2.0, 3)[4:].tolist() == [3.0, 3.0]  # at most ``most`` cells a side
    assert pack_hull(*hulls[-3]).grid[0, 2:].tolist() == [0.0, 0.0, 1.0, 1.0]  # no span: one column
    assert pack_hull(*hulls[-2]).grid[0, 2:].tolist() == [0.0, 0.0, 1.0, 1.0]  # 1 / 1e-310 overflows: one cell
    assert pack_hull(*hulls[-1]).grid[0].tolist() == [0.0, 0.0, 1 / 9, 1 / 9, 1.0, 1.0]  # every vertex's box


def test_packed_knows_the_lobes_it_was_just_asked_about(rng):
    from arboretum_server.decompose import clear

    lobes = _blob_lobes(rng, 6)
    pack, box = clear._packed(lobes)
    assert clear._LAST[0][0] == tuple(lobes) and clear._packed(list(lobes))[0] is pack
    moved = list(lobes)
    moved[2] = replace(lobes[2], segment=np.ones((3, 3)))  # a new branch, the same hull
    assert clear._packed(moved)[0] is pack and clear._LAST[0][0][2] is moved[2]
    grown = list(lobes)
    grown[2] = replace(lobes[2], hull_vertices=lobes[2].hull_vertices * 1.5)
    new, (lo, hi) = clear._packed(grown)
    assert new is not pack and np.allclose(hi[2], lobes[2].hull_vertices.max(axis=0) * 1.5)
    assert clear._packed(lobes)[0] is pack  # still kept by the hulls' ids
    assert len(clear._packed(lobes[:5])[0].first) == 6  # five lobes: another set


def test_bent_starts_are_the_first_main_vertices_outside_foreign_lobes(rng):
    from arboretum_server.decompose.clear import WORK, _outside_first, boxes, inside_foreign

    lobes = _blob_lobes(rng, 16)
    verts = rng.uniform(0, 1, (300, 3))
    order = np.argsort(np.linalg.norm(verts - 0.5, axis=1))
    WORK["hull_tests"] = 0
    out = ~inside_foreign(lobes, 0, verts[order], boxes(lobes))
    every = WORK["hull_tests"]
    assert 48 < out.sum() < 250
    for count in (1, 7, 48, 400):
        WORK["hull_tests"] = 0
        got = _outside_first(lobes, 0, verts, order, count, boxes(lobes))
        assert np.array_equal(got, order[out][:count])
        assert WORK["hull_tests"] < every if count < 48 else WORK["hull_tests"] <= every
    assert len(_outside_first(lobes, 0, verts, order[:0], 48, boxes(lobes))) == 0


def _reference_smooth(segments, limit, iterations=12, weight=0.5):
    """``smooth_polylines`` before session 23 (numpy, one step over every inner vertex at a time)."""
    lens = np.array([len(s) for s in segments])
    flat = np.concatenate(segments).astype(np.float64)
    orig = flat.copy()
    starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
    inner = np.ones(len(flat), bool)
    inner[starts] = False
    inner[starts + lens - 1] = False
    idx = np.flatnonzero(inner)
    lim = np.broadcast_to(np.asarray(limit, dtype=np.float64), (len(flat),))[idx]
    for _ in range(iterations):
        flat[idx] += weight * (0.5 * (flat[idx - 1] + flat[idx + 1]) - flat[idx])
        disp = flat[idx] - orig[idx]
        scale = np.minimum(1.0, lim / np.maximum(np.linalg.norm(disp, axis=1), 1e-300))
        flat[idx] = orig[idx] + disp * scale[:, None]
    return np.split(flat, np.cumsum(lens)[:-1])


def test_compiled_smoothing_gives_the_numpy_polylines_bit_for_bit(rng):
    from arboretum_server.decompose.smooth import _smooth_kernel, smooth_polylines

    assert callable(_smooth_kernel)
    clipped = 0
    for _ in range(300):
        segs = [np.cumsum(rng.normal(0, rng.choice([0.001, 0.01, 0.1]), (rng.integers(2, 50), 3)), axis=0)
                + rng.uniform(-5, 5, 3) for _ in range(rng.integers(1, 5))]
        limit = 0.012 if rng.random() < 0.5 else rng.uniform(0.004, 0.012, sum(map(len, segs)))
        got, want = smooth_polylines(segs, limit), _reference_smooth(segs, limit)
        assert len(got) == len(want) and all(np.array_equal(g, w) for g, w in zip(got, want))
        clipped += any(np.linalg.norm(g - s, axis=1).max() >= 0.004 for g, s in zip(got, segs))
    assert clipped > 50  # the limits bite, not only the midpoint steps
    line = np.array([[0.0, 0, 0], [1, 1, 0], [2, 0, 0]])
    (capped,) = smooth_polylines([line], limit=0.25)
    assert np.allclose(capped[1], [1, 0.75, 0]) and np.array_equal(capped[[0, 2]], line[[0, 2]])
