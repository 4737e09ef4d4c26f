"""Session 27 (helper-189): ``clear.foreign`` asks only whether any resampled vertex of a branch lies in a
foreign lobe, so it stops at the first one (``hullpack.any_inside``: every 4th vertex first, then the rest),
and the point tests list once per call the hulls whose box meets the points' box (``_hulls_meeting``). The
answers are those of testing every point hull by hull (``_point_inside``, the loop before), the counts of
``inside_any`` too; ``any_inside`` makes no more tests than ``inside_any``."""

from __future__ import annotations

import numpy as np


def _batches(rng, lobes):
    """Point batches like the ones the repairs test: resampled segments between random points and lobe centres
    (short ones meet a few boxes, long ones many), a batch with a NaN row, one far outside, an empty one."""
    out = []
    for _ in range(40):
        a = rng.uniform(-0.1, 1.1, 3)
        b = lobes[int(rng.integers(len(lobes)))].centre if rng.random() < 0.7 else rng.uniform(-0.1, 1.1, 3)
        m = int(rng.integers(2, 60))
        out.append(a + np.linspace(0.0, 1.0, m)[:, None] * (b - a))
    nan = out[0].copy()
    nan[1] = np.nan
    return [*out, nan, np.full((5, 3), 9.0), np.zeros((0, 3))]


def _lobe_sets(rng):
    from test_refine_s14_speed import _blob_lobes
    from test_refine_s23_speed import _alpha_lobes

    return [_blob_lobes(rng, 16), _alpha_lobes(rng)]


def _point_by_point(pack, lo, hi, skip, q):
    """The loop before session 27: every hull's box tried for every point (``_point_inside``)."""
    from arboretum_server.decompose.hullpack import _cells, _point_inside

    tests = np.zeros(1, np.int64)
    out = np.array([_point_inside(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi, pack.face_top,
                                  lo, hi, skip, x, y, z, tests) for x, y, z in q], bool)
    return out, int(tests[0])


def _boxes(lobes):
    """The lobes' own boxes, and the same with every box from the fourth on emptied (``kept_boxes``)."""
    from arboretum_server.decompose.clear import boxes, kept_boxes
    from arboretum_server.decompose.hullpack import _read_only

    return [boxes(lobes), tuple(_read_only(b) for b in kept_boxes(lobes, 3))]


def _cases(rng, skips):
    """(pack, lo, hi, skip, q) over every lobe set, box choice, query batch and skip."""
    from arboretum_server.decompose.clear import _packed

    for lobes in _lobe_sets(rng):
        pack = _packed(lobes)[0]
        for lo, hi in _boxes(lobes):
            for q in _batches(rng, lobes):
                for skip in skips:
                    yield pack, lo, hi, skip, q


def test_inside_any_gives_the_point_by_point_answers_and_counts(rng):
    from arboretum_server.decompose.hullpack import inside_any

    hits = 0
    for pack, lo, hi, skip, q in _cases(rng, (-1, 1)):
        want, want_tests = _point_by_point(pack, lo, hi, skip, q)
        got, tests = inside_any(pack, lo, hi, skip, q)
        assert np.array_equal(got, want) and tests == want_tests
        hits += int(want.any())
    assert hits > 40  # points inside and outside


def test_any_inside_is_the_any_of_inside_any_for_fewer_tests(rng):
    from arboretum_server.decompose.hullpack import any_inside, inside_any

    answers, fewer = [], 0
    for pack, lo, hi, skip, q in _cases(rng, (-1, 2)):
        every, every_tests = inside_any(pack, lo, hi, skip, q)
        found, tests = any_inside(pack, lo, hi, skip, q)
        assert found == bool(every.any())
        assert tests == every_tests if not found else 0 < tests <= every_tests
        answers.append(found)
        fewer += tests < every_tests
    assert 0 < sum(answers) < len(answers) and fewer > 20


def test_any_inside_tries_every_fourth_point_first():
    from arboretum_server.decompose.hullpack import any_inside, join_packs, pack_hull

    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    pack = join_packs([pack_hull(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))])
    lo, hi = np.full((1, 3), -1e-3), np.full((1, 3), 1.001)
    q = np.full((9, 3), 0.5)  # in the hull's box, outside the hull (x + y + z > 1)
    q[5] = q[8] = 0.1  # inside: 8 is a 4th point (0, 4, 8 first), 5 is not
    assert any_inside(pack, lo, hi, -1, q) == (True, 3)
    q[8] = 0.5
    assert any_inside(pack, lo, hi, -1, q) == (True, 7)  # 0, 4, 8, then 1, 2, 3, 5
    q[5] = 0.5
    assert any_inside(pack, lo, hi, -1, q) == (False, 9)
    assert any_inside(pack, lo, hi, 0, q) == (False, 0)


def test_foreign_is_the_any_of_inside_foreign(rng):
    from arboretum_server.decompose.clear import foreign, inside_foreign
    from arboretum_server.decompose.merge import resample_step

    answers = []
    for lobes in _lobe_sets(rng):
        for box in (None, *_boxes(lobes)):
            for q in _batches(rng, lobes)[:40]:
                for j in (0, 3):
                    want = bool(inside_foreign(lobes, j, resample_step(q, 0.01), box).any())
                    assert foreign(lobes, j, q, 0.01, box) == want
                    answers.append(want)
    assert 0 < sum(answers) < len(answers)


def test_unit_steps_are_linspace_bit_for_bit():
    from arboretum_server.decompose.clear import UNIT_STEPS_KEPT, unit_steps

    for m in [*range(2, 200), UNIT_STEPS_KEPT, UNIT_STEPS_KEPT + 1, 5000]:
        got = unit_steps(m)
        assert got.shape == (m, 1) and np.array_equal(got, np.linspace(0.0, 1.0, m)[:, None])
        assert got.tobytes() == np.linspace(0.0, 1.0, m)[:, None].tobytes()
    assert unit_steps(7) is unit_steps(7) and not unit_steps(7).flags.writeable
