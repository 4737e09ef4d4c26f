"""Session 24 (helper-172): ``hullpack.segments_blocked`` tests each start's first sample once per call, by a start
id (``clear.straight_from`` passes each pair's main vertex: ``tunnel.moved_centre`` asks for up to 32 centres from
the same 64 vertices; ``bent_fallback`` its vertex x waypoint pairs), and a segment whose start is known to lie
in a foreign hull is blocked at once: the answers and hull-test counts of testing sample by sample."""

from __future__ import annotations

import numpy as np


def _pairs(rng, n_starts: int = 12, n_ends: int = 10):
    """Every (start, end) pair, start after start, starts shuffled so equal starts are not all in a row, with
    the starts' ids."""
    starts = rng.uniform(-0.1, 1.1, (n_starts, 3))
    ends = rng.uniform(-0.1, 1.1, (n_ends, 3))
    ids = rng.permutation(np.repeat(np.arange(n_starts), n_ends))
    return starts[ids], ends[np.tile(np.arange(n_ends), n_starts)], ids


def test_start_ids_give_the_reference_answers_and_hull_tests(rng):
    from arboretum_server.decompose.clear import WORK, blocked, boxes, first_clear
    from test_refine_s14_speed import _blob_lobes, _reference_blocked
    from test_refine_s23_speed import _alpha_lobes
    from test_refine_s23_speed2 import _reference_tests

    for lobes in (_blob_lobes(rng, 16), _alpha_lobes(rng)):
        a, b, ids = _pairs(rng)
        want = _reference_blocked(lobes, 1, a, b, 0.02, boxes(lobes))
        WORK["hull_tests"] = 0
        got = blocked(lobes, 1, a, b, 0.02, boxes(lobes), ids)
        assert np.array_equal(got, want) and 0 < want.sum() < len(a)
        assert WORK["hull_tests"] == _reference_tests(lobes, 1, a, b, 0.02) > 0
        assert first_clear(lobes, 1, a, b, 0.02, boxes(lobes), ids) == int(np.argmin(want))


def test_a_start_inside_a_hull_blocks_every_segment_from_it():
    from arboretum_server.decompose.hullpack import join_packs, pack_hull, segments_blocked

    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    pack = join_packs([pack_hull(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))])
    lo, hi = np.full((1, 3), -1e-3), np.full((1, 3), 1.001)
    inner, outer = np.full(3, 0.1), np.full(3, 5.0)
    a = np.array([inner, outer, inner, outer, inner])
    b = np.array([outer, inner, [0.2, 0.1, 0.1], outer + 1, [np.nan, 0, 0]])  # the last: sample 0 is NaN
    counts = np.array([5, 5, 3, 4, 2])
    ids = np.array([0, 1, 0, 1, 0])
    out, tests = segments_blocked(pack, lo, hi, -1, a, b, counts, start_ids=ids)
    plain = [segments_blocked(pack, lo, hi, -1, a[i:i + 1], b[i:i + 1], counts[i:i + 1]) for i in range(len(a))]
    assert out.tolist() == [p[0][0] for p in plain] == [True, True, True, False, False]
    # a test for the inner start (reused for the third segment) and one for the second's last sample; the NaN
    # end makes the fifth one's samples NaN, which no box holds (its start's answer is not reused)
    assert tests == sum(p[1] for p in plain) == 3
