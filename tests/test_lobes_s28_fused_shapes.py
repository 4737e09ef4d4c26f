"""Session 28 (helper-196): a split's small pieces, their alpha shapes in fewer compiled calls, the same bits.
``Tetrahedra`` takes its circumspheres, flatness and radii in one loop over the corners' indices
(``tetloops.tetrahedra``); an uncarved shape is one call (``tetloops.plain_shape``: walled-in cut, boundary,
covered count, orientation, compaction and closedness level), a carved one three plus its pinch rounds
(``cut``, ``boundary``, ``pinched_edges``, ``finish``); ``without`` builds the blockers' KD-tree only for
spheres a blocker grazes. Each is held here against the numpy code it replaced."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from arboretum_server.decompose import lobes, tetloops


def _clouds(rng: np.random.Generator):
    """Small pieces (5-30 points, a split's), larger random clouds, rounded clouds and grids (flat tetrahedra,
    cospherical corners)."""
    for _ in range(20):
        yield rng.normal(size=(int(rng.integers(5, 31)), 3)) * 0.05
    for _ in range(8):
        yield rng.random((int(rng.integers(30, 400)), 3))
    for _ in range(6):
        yield np.round(rng.normal(size=(int(rng.integers(20, 200)), 3)) * 0.1, 2)
    for _ in range(4):  # a grid off by a rounding: slivers flat by ``FLAT`` yet with a finite circumsphere
        g = np.stack(np.meshgrid(*[np.arange(int(rng.integers(3, 6)))] * 3), -1).reshape(-1, 3) * 0.01
        yield g + 1e-13 * rng.random(g.shape)
    for _ in range(6):
        g = np.stack(np.meshgrid(*[np.arange(int(rng.integers(3, 7)))] * 3), -1).reshape(-1, 3) * 0.01
        yield g + rng.integers(0, 2, g.shape) * 1e-3


def _old_tetrahedra(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What ``Tetrahedra.__init__`` computed before: the gathered corners, circumspheres, flatness, inf radii."""
    corners = points[tets]
    centres, radii = tetloops.circumspheres_reference(corners)
    flat = tetloops.flat(corners, lobes.FLAT)
    radii[flat] = np.inf
    return centres, radii, flat


def _old_shape(tet: lobes.Tetrahedra, radius: float) -> tuple[np.ndarray, np.ndarray, int] | None:
    """``Tetrahedra.shape`` in numpy as it was, with ``is_closed_manifold_reference``'s answers as a level."""
    keep = lobes._walled_in(tet.neighbours, tet.flat, tet.radii < radius)
    if not keep.any():
        return None
    faces, opp = tetloops.boundary_reference(tet.tets, tet.neighbours, keep)
    for _ in range(lobes.PINCH_ROUNDS if tet.carve else 0):
        pinched = lobes._pinched_edges(faces)
        if not len(pinched):
            break
        tetloops.drop_edges_reference(tet.tets, keep, pinched)
        if not keep.any():
            break
        faces, opp = tetloops.boundary_reference(tet.tets, tet.neighbours, keep)
    if not keep.any() or tetloops.covered_reference(tet.tets, keep, len(tet.points)) < lobes.MIN_COVER * tet.n_own:
        return None
    faces = tetloops.orient_reference(tet.points, faces, opp)
    u, inv = np.unique(faces, return_inverse=True)
    f = inv.reshape(-1, 3).astype(np.int32)
    level = 2 if tetloops.is_closed_manifold_reference(f) else int(tetloops.is_closed_manifold_reference(f, False))
    return tet.points[u], f, level


def test_tetrahedra_loop_is_the_gathered_corners_code(rng):
    flat_seen = finite_flat = 0
    for pts in _clouds(rng):
        dt = Delaunay(pts)
        got, want = tetloops.tetrahedra(pts, dt.simplices, lobes.FLAT), _old_tetrahedra(pts, dt.simplices)
        assert np.array_equal(got[0], want[0], equal_nan=True)
        assert np.array_equal(got[1], want[1]) and np.array_equal(got[2], want[2])
        flat_seen += int(want[2].sum())
        finite_flat += int((want[2] & np.isfinite(tetloops.circumspheres_reference(pts[dt.simplices])[1])).sum())
    assert flat_seen > 5 and finite_flat > 5


def test_cut_is_walled_in(rng):
    filled = 0
    for pts in _clouds(rng):
        tet = lobes.Tetrahedra(pts)
        finite = tet.radii[np.isfinite(tet.radii)]
        for radius in np.quantile(finite, [0.1, 0.5, 0.9, 1.0]) * 1.0000001:
            want = lobes._walled_in(tet.neighbours, tet.flat, tet.radii < radius)
            assert np.array_equal(tetloops.cut(tet.neighbours, tet.flat, tet.radii, radius), want)
            filled += int((want & ~(tet.radii < radius)).sum())
    assert filled > 10


def test_pinched_edges_are_np_unique_counts(rng):
    pinched = 0
    for _ in range(200):
        n = int(rng.integers(4, 40))
        faces = rng.integers(0, n, (int(rng.integers(0, 120)), 3)).astype(np.int32)
        got, want = tetloops.pinched_edges(faces), lobes._pinched_edges(faces)
        assert got.dtype == want.dtype and np.array_equal(got, want)
        pinched += len(want)
    assert pinched > 500


def test_shapes_and_levels_match_the_numpy_code(rng):
    """Plain and carved shapes at every probe radius, and their closedness level, against the code before."""
    shapes, levels = 0, set()
    for pts in _clouds(rng):
        plain = lobes.Tetrahedra(pts)
        scale = float(np.ptp(pts, axis=0).max())
        blockers = pts[rng.integers(0, len(pts), 3)] + 0.05 * scale * rng.standard_normal((3, 3))
        for tet in (plain, plain.without(blockers)):
            for radius in np.array([0.1, 0.2, 0.4, 0.8, 2.0]) * scale:
                got, want = tet.leveled_shape(radius), _old_shape(tet, radius)
                assert (got is None) == (want is None)
                if got is not None:
                    assert np.array_equal(got[0], want[0]) and got[1].dtype == want[1].dtype
                    assert np.array_equal(got[1], want[1]) and got[2] == want[2]
                    assert np.array_equal(tet.shape(radius)[1], want[1])
                    shapes += 1
                    levels.add(got[2])
    assert shapes > 150 and levels == {0, 1, 2}


def test_without_skips_only_an_unused_kd_tree(rng):
    """The carved radii equal those of the code before, which asked the KD-tree about every unsure sphere."""
    grazed = 0
    for pts in _clouds(rng):
        tet = lobes.Tetrahedra(pts)
        for blockers in (pts[rng.integers(0, len(pts), 4)] + 1e-3 * rng.standard_normal((4, 3)),
                         tet.points[tet.tets[: 3, 0]].copy()):  # corners: on circumspheres, unsure
            live = np.flatnonzero(tet.radii < np.inf)
            held = tetloops.held(tet.centres[live], tet.radii[live], blockers)
            unsure = live[held == 2]
            want = tet.radii.copy()
            want[live[held == 1]] = np.inf
            near = cKDTree(blockers).query(tet.centres[unsure], distance_upper_bound=np.inf)[0]
            want[unsure[near < tet.radii[unsure]]] = np.inf
            assert np.array_equal(tet.without(blockers).radii, want)
            grazed += len(unsure)
    assert grazed > 20
