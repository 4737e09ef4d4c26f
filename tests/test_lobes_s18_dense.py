"""Session 18: lobes of points on a grid get alpha shapes, not convex hulls (lobes.FLAT, lobes._walled_in).

Scan 10 is stored at 1 cm; qhull splits its cells of four points on a circle into flat tetrahedra with no
true circumsphere, which the alpha shape left out as holes: 39 of its 40 lobes at ``--points 0`` were
convex fallbacks. With lobes.py as before the fix all six tests fail: the three on grids by value (alpha
shape refused; scan 10: 39 fallbacks), the others for want of ``FLAT``, ``Tetrahedra.flat``, ``_walled_in``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from arboretum_server.decompose import lobes
from arboretum_server.decompose.evaluate import signed_distances
from arboretum_server.decompose.tetloops import flat

RADIUS = 1 / 13  # the default probe radius at the 0.8 m scale
SCAN10 = Path(__file__).resolve().parents[1] / "assets/scans/10_treels_pine/10_treels_pine.xyz"


def _volume(v: np.ndarray, f: np.ndarray) -> float:
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def _consistently_oriented(f: np.ndarray) -> bool:
    """Every directed edge once: neighbouring faces agree on which side is out."""
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).astype(np.int64)
    return len(np.unique(d[:, 0] * (int(f.max()) + 1) + d[:, 1])) == len(d)


def _lattice_l_slab() -> np.ndarray:
    """An L of 1.5 cm lattice points (924), 28.5 cm across and 4.5 cm thick: every cell's corners lie on a
    sphere."""
    g = np.arange(0, 0.30, 0.015)
    x = np.stack(np.meshgrid(g, g, g[:4], indexing="ij"), -1).reshape(-1, 3)
    return x[~((x[:, 0] > 0.1) & (x[:, 1] > 0.1))]


def test_flat_marks_only_degenerate_tetrahedra():
    square = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    regular = [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]
    sliver = [[0, 0, 0], [1, 0, 0], [1, 1, 1e-6], [0, 1, 0]]  # 6 V = 1e-6: a real (if thin) tetrahedron
    got = flat(np.array([square, regular, sliver], dtype=float), lobes.FLAT)
    assert got.tolist() == [True, False, False]


def test_flat_tetrahedra_have_no_radius():
    tet = lobes.Tetrahedra(_lattice_l_slab())
    assert tet.flat.sum() > 50
    assert np.isinf(tet.radii[tet.flat]).all()
    assert np.isfinite(tet.radii[~tet.flat]).all()


def test_walled_in_fills_only_enclosed_flat_tetrahedra():
    # 0, 1: flat, next to each other and otherwise to kept 2-5; 6: flat, on the outside (-1); 7: flat,
    # next to a dropped 8; 9: flat and kept already
    nb = np.array([[1, 2, 3, 4], [0, 5, 2, 3], [0, 1, 3, 4], [0, 1, 2, 4], [0, 2, 3, 5], [1, 2, 3, 4],
                   [2, 3, 4, -1], [2, 3, 4, 8], [7, 2, 3, 4], [2, 3, 4, 5]])
    is_flat = np.zeros(10, bool)
    is_flat[[0, 1, 6, 7, 9]] = True
    keep = np.zeros(10, bool)
    keep[[2, 3, 4, 5, 9]] = True
    got = lobes._walled_in(nb, is_flat, keep)
    assert np.flatnonzero(got).tolist() == [0, 1, 2, 3, 4, 5, 9]
    assert np.flatnonzero(keep).tolist() == [2, 3, 4, 5, 9]  # the input is not changed


def test_lattice_l_slab_gets_a_closed_alpha_shape():
    p = _lattice_l_slab()
    v, f, used_alpha = lobes.lobe_hull(p, RADIUS)
    assert used_alpha
    assert lobes.is_closed_manifold(f) and _consistently_oriented(f)
    vol, convex = _volume(v, f), ConvexHull(p).volume
    assert 0.00194 < vol < 0.75 * convex  # the L's cells hold 0.00194 m^3, its convex hull 0.00280 (0.00207)
    assert (signed_distances(v, f, p) <= 0.01).all()  # the leaf cover's tolerance


@pytest.fixture(scope="module")
def scan10() -> np.ndarray:
    pts = np.loadtxt(SCAN10)[:, :3]
    return (pts - pts.min(axis=0)) * (0.8 / np.ptp(pts[:, 2]))  # the 0.8 m frame, its 1 cm grid 0.4 mm


def test_scan10_crops_get_alpha_shapes(scan10):
    """Balls of 4 cm round 8 points of scan 10 (3,500-6,600 points, so thinned as dense lobes): 2 were
    convex hulls before."""
    centres = scan10[np.random.default_rng(0).choice(len(scan10), 8)]
    for c in centres:
        p = scan10[np.linalg.norm(scan10 - c, axis=1) < 0.04]
        v, f, used_alpha = lobes.lobe_hull(p, RADIUS)
        assert used_alpha, len(p)
        assert _consistently_oriented(f)
        assert (signed_distances(v, f, p) <= 0.01).mean() > 0.999


def test_scan10_full_resolution_has_no_convex_fallbacks(scan10):
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    d = decompose(np.loadtxt(SCAN10)[:, :3], DecomposeOptions(points=0))
    assert (d.stats["lobes"], d.stats["hull_fallbacks"]) == (40, 0)  # 39 fallbacks before
