"""Session 25 (helper-177): the repairs remember, for one ``make_lobes`` call, which hull blocked each segment from a
main vertex (``blockers.Blockers``), and a segment whose blocking hull is still there (same arrays, own box) is
blocked without a test (``hullpack.segments_blocked``'s ``prior``); ``tunnel.behind`` tries the kept lobes alone
through emptied boxes (``clear.kept_boxes``) instead of packing a list of them per lobe. The same answers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np


def _mains():
    """A BranchSet with one vertical main branch through the 1 m cube of ``_blob_lobes`` (a vertex every 2 cm)."""
    from arboretum_server.decompose.merge import BranchSet

    z = np.linspace(-0.2, 1.2, 71)
    return BranchSet(segments=[np.stack([np.full_like(z, 0.5), np.full_like(z, 0.45), z], axis=1)])


def _lobes(rng, n=16):
    from test_refine_s14_speed import _blob_lobes

    lobes = _blob_lobes(rng, n)
    pts = rng.uniform(0, 1, (40 * n, 3))
    return [replace(lb, members=np.arange(40 * k, 40 * k + 40)) for k, lb in enumerate(lobes)], pts


def test_a_known_blocker_blocks_without_a_test_and_by_names_a_hull_holding_a_sample(rng):
    from arboretum_server.decompose.clear import _packed, _sample_counts, _segment_samples, boxes
    from arboretum_server.decompose.hullpack import segments_blocked
    from arboretum_server.decompose.lobes import inside
    from test_refine_s14_speed import _blob_lobes

    lobes = _blob_lobes(rng, 16)
    a, b = rng.uniform(0, 1, (300, 3)), rng.uniform(0, 1, (300, 3))
    pack, (lo, hi) = _packed(lobes), boxes(lobes)
    counts = _sample_counts(a, b, 0.02)
    by = np.full(len(a), -1, np.int64)
    want, tests = segments_blocked(pack[0], lo, hi, 1, a, b, counts, by=by)
    assert 0 < want.sum() < len(a) and tests > 0
    assert np.array_equal(by >= 0, want) and not (by == 1).any()
    samples, which = _segment_samples(a, b, 0.02)
    for i in np.flatnonzero(want):
        k = by[i]
        assert inside(lobes[k].hull_vertices, lobes[k].hull_faces, samples[which == i]).any()
    again, fewer = segments_blocked(pack[0], lo, hi, 1, a, b, counts, prior=by)
    clear_only = segments_blocked(pack[0], lo, hi, 1, a[~want], b[~want], counts[~want])[1]
    assert np.array_equal(again, want) and fewer == clear_only < tests  # the blocked ones cost no hull test
    half = np.where(np.arange(len(a)) % 2 == 0, by, -1)
    again, some = segments_blocked(pack[0], lo, hi, 1, a, b, counts, prior=half)
    assert np.array_equal(again, want) and 0 < some < tests


def test_kept_boxes_try_the_kept_lobes_alone(rng):
    from arboretum_server.decompose.clear import bent_fallback, kept_boxes, straight_routes

    lobes, pts = _lobes(rng)
    mains, n = _mains(), 10
    for j in range(n, len(lobes)):
        sub = [*lobes[:n], lobes[j]]
        got = straight_routes(lobes, j, mains, box=kept_boxes(lobes, n))
        want = straight_routes(sub, n, mains)
        assert len(got) == len(want) and all(np.array_equal(g[0], w[0]) and g[1:] == w[1:] for g, w in zip(got, want))
        got, want = bent_fallback(lobes, j, mains, pts, box=kept_boxes(lobes, n)), bent_fallback(sub, n, mains, pts)
        assert (got is None) == (want is None)
        assert got is None or (np.array_equal(got[0], want[0]) and got[1:] == want[1:])


def test_the_repairs_give_the_same_answers_with_the_blockers_they_remember(rng):
    from arboretum_server.decompose import clear
    from arboretum_server.decompose.blockers import forget_blockers
    from arboretum_server.decompose.clear import bent_fallback, straight_fallback, straight_from

    def answers(lobes, j, pts, mains):
        s, b = straight_fallback(lobes, j, mains), bent_fallback(lobes, j, mains, pts)
        own = np.arange(0, 40, 3)
        m = straight_from(lobes, j, pts[lobes[j].members[own]], mains, own=(own, pts))
        return [None if x is None else (x[0].tolist(), x[1:]) for x in (s, b)] + [None if m is None else m[0]]

    lobes, pts = _lobes(rng)
    mains = _mains()
    shrunk = [replace(lb, hull_vertices=lb.centre + 0.6 * (lb.hull_vertices - lb.centre)) for lb in lobes]
    checked = 0
    for j in range(len(lobes)):
        after = [shrunk[k] if k in (j - 1, j + 1) else lb for k, lb in enumerate(lobes)]  # two hulls carved
        forget_blockers()
        clear.WORK["hull_tests"] = 0
        want = answers(after, j, pts, mains)
        fresh = clear.WORK["hull_tests"]
        forget_blockers()
        answers(lobes, j, pts, mains)  # remembered, then asked again with two hulls changed
        clear.WORK["hull_tests"] = 0
        assert answers(after, j, pts, mains) == want
        assert clear.WORK["hull_tests"] <= fresh
        checked += clear.WORK["hull_tests"] < fresh
    forget_blockers()
    assert checked > 0
