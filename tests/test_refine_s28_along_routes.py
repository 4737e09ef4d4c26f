"""Session 28 (helper-194): ``tunnel.along`` makes its routes (the split lobe's branch up to a vertex, then
straight to the piece's centre) and asks ``clear.foreign`` of each, up to the first clear one, in one compiled
call (``clear.first_clear_along``, ``hullpack.first_clear_route``), and ``tunnel._clear_prefix`` tests a branch's
prefixes in one call too (``clear.clear_prefix_length``). Each gives the answer and the hull-test count of the
route-by-route loop before it; ``_along_order`` gives each route's point count as ``np.linalg.norm`` of its gap."""

from __future__ import annotations

import numpy as np


def _lobe_sets(rng):
    from test_refine_s14_speed import _blob_lobes
    from test_refine_s23_speed import _alpha_lobes

    return [_blob_lobes(rng, 16), _alpha_lobes(rng)]


def _branches(rng, lobes):
    """Polylines like a split lobe's branch: from outside the lobes towards and through them, 1-40 vertices."""
    out = []
    for _ in range(25):
        n = int(rng.integers(1, 40))
        a = rng.uniform(-0.2, 1.2, 3)
        b = lobes[int(rng.integers(len(lobes)))].centre
        out.append(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a) + rng.normal(0.0, 0.01, (n, 3)))
    return out


def _counted(fn, *args):
    """(fn(*args), hull tests it made)."""
    from arboretum_server.decompose.clear import WORK

    before = WORK["hull_tests"]
    out = fn(*args)
    return out, WORK["hull_tests"] - before


def _route_by_route(lobes, j, seg, centre, tol, box):
    """The loop of ``along`` before session 28: the first route ``foreign`` finds clear, -1 for none."""
    from arboretum_server.decompose.clear import foreign
    from arboretum_server.decompose.tunnel import _along_route_iter

    for i, route in enumerate(_along_route_iter((seg, 0, 0), centre)):
        if not foreign(lobes, j, route, tol, box):
            return i
    return -1


def test_first_clear_along_is_the_route_by_route_loop(rng):
    from arboretum_server.decompose.clear import boxes, first_clear_along, kept_boxes
    from arboretum_server.decompose.tunnel import _along_order

    found = []
    for lobes in _lobe_sets(rng):
        for box in (boxes(lobes), kept_boxes(lobes, 3)):
            for seg in _branches(rng, lobes):
                for j in (0, 3):
                    centre = lobes[j].centre
                    order, counts = _along_order(seg, centre)
                    want, want_tests = _counted(_route_by_route, lobes, j, seg, centre, 0.0025, box)
                    (got, resume), tests = _counted(first_clear_along, lobes, j, seg, centre, order, counts, 0.0025,
                                                    box)
                    assert (got, resume, tests) == (want, -1, want_tests)
                    found.append(got)
    assert sum(f < 0 for f in found) > 5 and sum(f == 0 for f in found) > 5 and sum(f > 0 for f in found) >= 2


def _prefix_by_prefix(lobes, j, seg, tol, box):
    """``tunnel._clear_prefix`` before session 28: one ``foreign`` call per prefix."""
    from arboretum_server.decompose.clear import foreign

    ok = 0
    while ok < len(seg) and not foreign(lobes, j, seg[: ok + 1], tol, box):
        ok += 1
    return ok


def test_clear_prefix_is_the_prefix_by_prefix_loop(rng):
    from arboretum_server.decompose.clear import boxes, clear_prefix_length

    oks = []
    for lobes in _lobe_sets(rng):
        box = boxes(lobes)
        for seg in _branches(rng, lobes):
            for j in (0, 3):
                want, want_tests = _counted(_prefix_by_prefix, lobes, j, seg, 0.0025, box)
                (ok, resume), tests = _counted(clear_prefix_length, lobes, j, seg, 0.0025, box)
                assert (ok, resume, tests) == (want, -1, want_tests)
                oks.append((ok, len(seg)))
    assert sum(ok == 0 for ok, _ in oks) > 3 and sum(0 < ok < n for ok, n in oks) > 3
    assert sum(ok == n for ok, n in oks) >= 3


def test_along_order_counts_are_those_of_each_gap_norm(rng):
    from arboretum_server.decompose.tunnel import _along_order

    for it in range(2000):
        n = int(rng.integers(1, 30))
        seg = np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0)
        centre = rng.normal(0.0, 0.05, 3)
        if it % 3 == 0:  # gaps of whole centimetres, where the ceiling is decided by the last bit
            centre = seg[int(rng.integers(n))] + np.array([0.01 * int(rng.integers(0, 6)), 0.0, 0.0])
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(seg, axis=0), axis=1))])
        want = np.argsort(arc + np.linalg.norm(seg - centre, axis=1), kind="stable")
        counts = [max(2, int(np.ceil(float(np.linalg.norm(centre - seg[v])) / 0.01)) + 1) for v in want]
        order, got = _along_order(seg, centre)
        assert np.array_equal(order, want) and got.tolist() == counts


def test_the_route_kernel_is_along_s_route_bit_for_bit(rng):
    from arboretum_server.decompose.hullpack import _along_route_kernel
    from arboretum_server.decompose.tunnel import _along_route

    for _ in range(3000):
        n = int(rng.integers(1, 20))
        seg = np.cumsum(rng.normal(0.0, 0.02, (n, 3)), axis=0)
        centre = rng.normal(0.0, 0.1, 3)
        v, m = int(rng.integers(n)), int(rng.integers(2, 1100))
        got, want = _along_route_kernel(seg, centre, v, m), _along_route(seg, centre, v, m)
        assert got.shape == want.shape and got.tobytes() == want.tobytes()


def test_the_routes_kernel_makes_along_s_routes():
    """A route through a hull only by its straight part's last sample: the kernel finds it blocked, so its
    linspace and resampling reach the centre as ``_along_route`` does."""
    from arboretum_server.decompose.hullpack import first_clear_route, join_packs, pack_hull

    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    pack = join_packs([pack_hull(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))])
    lo, hi = np.full((1, 3), -1e-3), np.full((1, 3), 1.001)
    seg = np.array([[-1.0, 0.1, 0.1], [-0.5, 0.1, 0.1]])
    assert first_clear_route(pack, lo, hi, -1, seg, np.array([0.1, 0.1, 0.1]), np.array([1, 0]),
                             np.array([3, 5]), 0.01)[0] == -1
    assert first_clear_route(pack, lo, hi, -1, seg, np.array([-0.1, 0.1, 0.1]), np.array([1, 0]),
                             np.array([3, 5]), 0.01)[0] == 0
    assert first_clear_route(pack, lo, hi, 0, seg, np.array([0.1, 0.1, 0.1]), np.array([1]), np.array([3]),
                             0.01) == (0, 0, -1)

