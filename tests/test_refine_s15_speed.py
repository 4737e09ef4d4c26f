"""Refinement's compiled kernels and remembered main references (session 15, helper-118).

Every "around" insert of the leaf-on pine went through numpy code with small arrays many times over:
chi-square cost matrices, arc-length resampling, circumspheres, alpha-shape boundaries and closedness
tests, and the main branches' shape contexts were computed again by every ``make_lobes`` call. Each fast
version is held here to its slow reference bit for bit (``np.array_equal``, not a tolerance), and a
refinement run with the references swapped in gives the same lobes, arrays equal to the last bit."""

from __future__ import annotations

import gc

import numpy as np
import pytest


@pytest.fixture(scope="module")
def toy():
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts, _ = toy_scan(toy_truth(), n=6000, seed=1)
    return decompose(pts, DecomposeOptions(n_main=3, n_lobes=10))


def _refinements(d):
    """Four refinements of ``d`` (each kind once), as thunks."""
    from arboretum_server.decompose import refine

    lobe = d.hbl.lobes[4].points
    return [lambda: refine.remove_lobe(d, 3),
            lambda: refine.insert_lobe(d, d.lobes[0].members[: len(d.lobes[0].members) // 2]),
            lambda: refine.merge_lobes(d, [1, 2]),
            lambda: refine.split_lobe(d, 4, [lobe[:2], lobe[-2:]])]


def test_main_shape_contexts_are_computed_once_across_refinements(toy, monkeypatch):
    """Before session 15 every ``make_lobes`` call (one to three per refinement) computed the main
    branches' shape contexts again: 4 refinements made at least 4 such calls."""
    from arboretum_server.decompose import merge

    refs = [toy.mains.reference(b) for b in range(len(toy.mains.full))]
    calls = []
    real = merge._hists

    def counting(polylines, n, bins):
        if len(polylines) == len(refs) and all(p is r for p, r in zip(polylines, refs)):
            calls.append(1)
        return real(polylines, n, bins)

    monkeypatch.setattr(merge, "_hists", counting)
    for op in _refinements(toy):
        op()
    assert len(calls) <= 1  # at most once, when the decomposition's own call is no longer remembered
    for op in _refinements(toy):
        op()
    assert len(calls) <= 1


def test_main_references_follow_the_arrays_they_were_computed_for():
    from arboretum_server.decompose.merge import (
        _REFERENCES,
        BranchSet,
        _hists,
        add_branch,
        main_references,
    )

    rng = np.random.default_rng(5)
    trunk = np.cumsum(rng.normal(0, 0.01, (30, 3)), axis=0)
    first = BranchSet()
    add_branch(first, trunk, -1, -1)
    add_branch(first, np.vstack([trunk[10], trunk[10] + np.cumsum(rng.normal(0, 0.01, (12, 3)), axis=0)]), 0, 10)
    second = BranchSet(first.segments[:1], first.parents[:1], first.parent_vertex[:1], first.full[:1],
                       first.owner[:1])  # shares the trunk's array, not the second branch
    add_branch(second, np.vstack([trunk[20], trunk[20] + np.cumsum(rng.normal(0, 0.01, (9, 3)), axis=0)]), 0, 20)
    for mains in (first, second, first):
        refs, hists, trees = main_references(mains, 24, (5, 6, 4))
        assert np.array_equal(hists, _hists([mains.reference(b) for b in range(2)], 24, (5, 6, 4)))
        assert [t.query(r[-1])[0] for t, r in zip(trees, refs)] == [0.0, 0.0]
    key = id(first.full[0])
    assert key in _REFERENCES
    del first, second, refs, hists, trees, mains, trunk
    gc.collect()
    assert key not in _REFERENCES  # the entry goes with its arrays


def _shape_contexts_reference(branches, bins):
    """``similarity.shape_contexts`` before session 15 (``np.add.at``)."""
    from arboretum_server.decompose.similarity import R_INNER, R_OUTER

    nr, na, ne = bins
    b, n, _ = branches.shape
    v = branches[:, None, :, :] - branches[:, :, None, :]
    r = np.linalg.norm(v, axis=3)
    off = ~np.eye(n, dtype=bool)[None]
    mean = np.maximum((r * off).sum(axis=(1, 2)) / (n * (n - 1)), 1e-12)
    ri = np.clip(np.searchsorted(np.geomspace(R_INNER, R_OUTER, nr + 1), r / mean[:, None, None]) - 1, 0, nr - 1)
    ai = np.clip(((np.arctan2(v[..., 1], v[..., 0]) + np.pi) / (2 * np.pi) * na).astype(int), 0, na - 1)
    el = np.arcsin(np.clip(v[..., 2] / np.maximum(r, 1e-12), -1.0, 1.0))
    ei = np.clip(((el + np.pi / 2) / np.pi * ne).astype(int), 0, ne - 1)
    hist = np.zeros((b, n, nr * na * ne))
    bi, ii, _ = np.nonzero(np.broadcast_to(off, (b, n, n)))
    np.add.at(hist, (bi, ii, ((ri * na + ai) * ne + ei)[off.repeat(b, axis=0)]), 1.0)
    return hist / (n - 1)


@pytest.mark.parametrize("bins", [(5, 6, 4), (2, 3, 2), (4, 4, 8), (1, 1, 1), (8, 8, 8)])
def test_shape_contexts_and_chi_square_match_their_references(rng, bins):
    from arboretum_server.decompose.similarity import (
        chi_square,
        chi_square_reference,
        shape_contexts,
    )

    for n in (2, 5, 24, 41):
        branches = np.cumsum(rng.normal(0, 0.01, (4, n, 3)), axis=0)
        h = shape_contexts(branches, bins)
        assert np.array_equal(h, _shape_contexts_reference(branches, bins))
        for x in range(4):
            for y in range(4):
                assert np.array_equal(chi_square(h[x], h[y]), chi_square_reference(h[x], h[y]))
    for k in (1, 7, 8, 9, 120, 127, 128, 129, 300):  # dense and sparse rows, k % 8 tails, numpy's halving
        a = rng.random((6, k)) * (rng.random((6, k)) < 0.4)
        b = rng.random((5, k)) * (rng.random((5, k)) < 0.7)
        assert np.array_equal(chi_square(a, b), chi_square_reference(a, b))


def test_resample_step_matches_numpy_interp(rng):
    from arboretum_server.decompose.merge import resample_step, resample_step_reference

    cases = [np.zeros((1, 3)), np.zeros((2, 3)), np.array([[0.0, 0, 0], [0, 0, 1e-3], [0, 0, 1e-3], [0, 1, 1]])]
    for m in (2, 3, 4, 5, 17, 80):
        p = np.cumsum(rng.normal(0, 0.01, (m, 3)), axis=0)
        p[m // 2] = p[m // 2 - 1]  # a zero-length piece
        cases.append(p)
    for p in cases:
        for step in (0.0005, 0.0025, 0.01, 0.3):
            fast, slow = resample_step(p, step), resample_step_reference(p, step)
            assert fast.shape == slow.shape and np.array_equal(fast, slow)


def test_tetrahedra_kernels_match_their_references(rng):
    from arboretum_server.decompose import lobes, tetloops

    for n in (5, 40, 300):
        pts = rng.random((n, 3))
        pts[: n // 5, 2] = 0.5  # a flat patch: degenerate tetrahedra
        tet = lobes.Tetrahedra(pts)
        p = tet.points[tet.tets]
        fast, slow = lobes._circumspheres(p), tetloops.circumspheres_reference(p)
        assert np.array_equal(fast[0], slow[0], equal_nan=True) and np.array_equal(fast[1], slow[1])
        for radius in (0.05, 0.15, 0.5):
            keep = tet.radii < radius
            faces, opp = lobes._boundary(tet.tets, tet.neighbours, keep)
            ref_faces, ref_opp = tetloops.boundary_reference(tet.tets, tet.neighbours, keep)
            assert faces.dtype == ref_faces.dtype and np.array_equal(faces, ref_faces)
            assert np.array_equal(opp, ref_opp)
            shape = tet.shape(radius)
            if shape is None:
                continue
            for f in (shape[1], shape[1][1:], np.vstack([shape[1], shape[1][:4] + len(shape[0])])):
                for one in (True, False):
                    assert lobes.is_closed_manifold(f, one) == tetloops.is_closed_manifold_reference(f, one)


def test_carving_tests_only_the_spheres_its_radii_can_keep(rng):
    from arboretum_server.decompose.lobes import Tetrahedra

    tet = Tetrahedra(rng.random((400, 3)))
    blockers = rng.random((30, 3))
    full, bounded = tet.without(blockers), tet.without(blockers, 0.2)
    for radius in (0.05, 0.1, 0.2):
        a, b = full.shape(radius), bounded.shape(radius)
        assert (a is None) == (b is None)
        if a is not None:
            assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_carving_answers_as_the_kd_tree_query_did(rng):
    """``Tetrahedra.without`` before session 15: one KD-tree query of every circumcentre; blockers exactly on
    circumspheres (a tetrahedron's own vertices) are the cases ``_held`` leaves to that query."""
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.lobes import Tetrahedra, _held  # tetloops.held

    for n, m in ((300, 40), (60, 1), (500, 400)):
        tet = Tetrahedra(rng.random((n, 3)))
        blockers = np.vstack([rng.random((m, 3)), tet.points[tet.tets[:15, 0]]])
        live = np.flatnonzero(np.isfinite(tet.radii))
        expect = tet.radii.copy()
        expect[live[cKDTree(blockers).query(tet.centres[live])[0] < tet.radii[live]]] = np.inf
        assert np.array_equal(tet.without(blockers).radii, expect)
        assert (_held(tet.centres[live], tet.radii[live], blockers) == 2).any()  # the KD-tree decided some


def _first_far(cand: np.ndarray, ref: np.ndarray, tau: float) -> int:
    """The first vertex of ``cand`` at least ``tau`` from every vertex of ``ref`` (brute force), else its length."""
    d = np.linalg.norm(cand[:, None, :] - ref[None, :, :], axis=2).min(axis=1)
    far = np.flatnonzero(d >= tau)
    return int(far[0]) if len(far) else len(cand)


def test_merged_prefixes_match_one_reference_at_a_time(rng):
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.merge import merged_prefix, merged_prefixes

    cands = [np.cumsum(rng.normal(0, 0.01, (m, 3)), axis=0) for m in (1, 2, 9, 30)]
    refs = [np.cumsum(rng.normal(0, 0.01, (m, 3)), axis=0) for m in (1, 12, 40)]
    for tau in (0.0, 0.005, 0.02, 1.0):
        expect = np.array([[_first_far(c, r, tau) for r in refs] for c in cands])
        assert np.array_equal(merged_prefixes(cands, [cKDTree(r) for r in refs], tau), expect)
        assert np.array_equal(np.stack([merged_prefix(cands, r, tau) for r in refs], axis=1), expect)


def _arrays(d):
    return [x for lb in d.lobes for x in (lb.members, lb.centre, lb.hull_vertices, lb.hull_faces, lb.segment,
                                          np.array([lb.parent, lb.parent_vertex]))]


def test_refinements_with_the_slow_references_give_the_same_lobes(toy, monkeypatch):
    from arboretum_server.decompose import (
        carve,
        clear,
        lobes,
        merge,
        refine,
        secondary,
        similarity,
        tetloops,
        tunnel,
    )
    from arboretum_server.decompose.memo import ArrayMemo

    fast = [_arrays(op()) for op in _refinements(toy)]

    def uncached(mains, n, bins):
        refs = [mains.reference(b) for b in range(len(mains.full))]
        return refs, merge._hists(refs, n, bins), [merge.cKDTree(f) for f in refs]

    for mod in (merge, clear, refine, secondary, tunnel):
        if hasattr(mod, "resample_step"):
            monkeypatch.setattr(mod, "resample_step", merge.resample_step_reference)
    monkeypatch.setattr(secondary, "main_references", uncached)
    monkeypatch.setattr(similarity, "chi_square", similarity.chi_square_reference)
    monkeypatch.setattr(lobes, "_circumspheres", tetloops.circumspheres_reference)
    monkeypatch.setattr(lobes, "_boundary", tetloops.boundary_reference)
    monkeypatch.setattr(lobes, "is_closed_manifold", tetloops.is_closed_manifold_reference)
    monkeypatch.setattr(carve, "_CARVED", ArrayMemo())  # no carved shape recalled from the fast run
    monkeypatch.setattr(carve, "_PLAIN", ArrayMemo())
    slow = [_arrays(op()) for op in _refinements(toy)]
    for a, b in zip(fast, slow):
        assert len(a) == len(b) and all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(a, b))
