"""Dense lobes (``decompose --points 0``) are tetrahedralised on a thinned subset of their points."""

from __future__ import annotations

import numpy as np

from arboretum_server.decompose import carve
from arboretum_server.decompose.evaluate import signed_distances
from arboretum_server.decompose.lobes import DENSE, THIN, Tetrahedra, plain_hull, thin

RADIUS = 1 / 13


def _crown_patch(rng: np.random.Generator, n: int) -> np.ndarray:
    """A lobe-like cluster: ``n`` points in the outer tenth of a flattened ball 0.2 m across (leaves)."""
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return d * rng.uniform(0.9, 1.0, (n, 1)) * [0.1, 0.08, 0.06]


def test_thin_keeps_the_farthest_point_of_each_cube(rng):
    pts = rng.uniform(0, 0.1, (5000, 3))
    cell = 0.01
    out = thin(pts, cell)
    key = np.floor((pts - pts.min(axis=0)) / cell).astype(int)
    cubes = {tuple(k) for k in key}
    assert len(out) == len(cubes)  # one point per occupied cube
    far = np.linalg.norm(pts - pts.mean(axis=0), axis=1)
    best = {}
    for k, f, p in zip(map(tuple, key), far, pts):
        if k not in best or f > best[k][0]:
            best[k] = (f, tuple(p))
    assert {tuple(p) for p in out} == {p for _, p in best.values()}
    assert thin(pts, 0.0) is pts


def test_dense_lobes_are_built_on_a_thinned_cluster_that_still_covers_it(rng):
    pts = _crown_patch(rng, 12000)
    tet = Tetrahedra(pts, RADIUS / THIN)
    assert len(pts) > DENSE and tet.n_own < len(pts) / 2
    assert np.array_equal(tet.source, pts) and len(thin(tet.points, RADIUS / THIN)) == tet.n_own
    verts, faces, used_alpha, _, _ = plain_hull(pts, RADIUS)
    full = Tetrahedra(pts).shape(RADIUS)  # the whole cluster, not thinned
    assert used_alpha and full is not None

    def volume(v, f):
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        return float((a * np.cross(b, c)).sum() / 6)

    assert abs(volume(verts, faces) / volume(*full) - 1) < 0.01  # 0.1 % measured
    outside = signed_distances(verts, faces, pts)  # > 0 outside
    assert outside.max() <= 0.002  # 0.9 mm measured; the leaf-cover tolerance is 10 mm


def test_small_lobes_are_not_thinned(rng):
    pts = _crown_patch(rng, DENSE)
    tet = Tetrahedra(pts, RADIUS / THIN)
    assert tet.n_own == DENSE and tet.points is tet.source


def test_a_thinned_lobe_is_recalled_by_its_points(rng):
    pts = _crown_patch(rng, 3000)
    members = np.arange(len(pts))
    tet = Tetrahedra(pts, RADIUS / THIN)
    carve.remember_plain(members, tet)
    assert carve._recall_plain(members, pts) is tet  # by the cluster's points, not the thinned ones
