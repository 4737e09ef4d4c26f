"""The crown's inside test: the same grid as the dense ray-parity method, in bounded memory."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from arboretum_server.modules.crown import _inside_grid, crown_from_meshes
from arboretum_server.modules.shapes import box_mesh, sphere_mesh, tetrahedron_mesh, torus_mesh


def _dense_inside(vertices, faces, xs, ys, zs) -> np.ndarray:
    """The former method (reference): every triangle against 256 rows at once, a (256, nx, F) array."""
    tri = vertices[faces]
    yy, zz = np.meshgrid(ys + 1.234567e-7, zs + 7.654321e-8, indexing="ij")
    qy, qz = yy.ravel()[:, None], zz.ravel()[:, None]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    den = (b[:, 1] - a[:, 1]) * (c[:, 2] - a[:, 2]) - (c[:, 1] - a[:, 1]) * (b[:, 2] - a[:, 2])
    ok = np.abs(den) > 1e-300
    a, b, c, den = a[ok], b[ok], c[ok], den[ok]
    inside = np.zeros((len(xs), len(ys) * len(zs)), dtype=bool)
    for start in range(0, len(qy), 256):
        py, pz = qy[start : start + 256], qz[start : start + 256]
        l1 = ((b[:, 1] - py) * (c[:, 2] - pz) - (c[:, 1] - py) * (b[:, 2] - pz)) / den
        l2 = ((c[:, 1] - py) * (a[:, 2] - pz) - (a[:, 1] - py) * (c[:, 2] - pz)) / den
        l3 = 1 - l1 - l2
        hit = (l1 >= 0) & (l2 >= 0) & (l3 >= 0)
        xhit = np.where(hit, l1 * a[:, 0] + l2 * b[:, 0] + l3 * c[:, 0], np.inf)
        crossings = (xhit[:, None, :] < xs[None, :, None]).sum(axis=2)
        inside[:, start : start + 256] = (crossings % 2 == 1).T
    return inside.reshape(len(xs), len(ys), len(zs))


def _grid(vertices, resolution: int = 40):
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    step = float((hi - lo).max()) / resolution
    lo, hi = lo - 3 * step, hi + 3 * step
    return [np.arange(lo[k], hi[k] + step, step) for k in range(3)]


SHAPES = {
    "sphere": sphere_mesh([0.3, -0.2, 5], 3),
    "torus": torus_mesh([0, 0, 5], 2.5, 1.0, axis="x"),
    "tetrahedron": tetrahedron_mesh([0, 0, 4.6], 6.5),
    "box": box_mesh([0.0, 0.0, 0.0], [1.0, 2.0, 3.0]),  # axis-aligned faces: rays along their edges
}


@pytest.mark.parametrize("name", list(SHAPES))
@pytest.mark.parametrize("block", [1 << 19, 7])
def test_inside_grid_equals_the_dense_method(name, block):
    v, f = SHAPES[name]
    v = np.asarray(v, dtype=np.float64)
    xs, ys, zs = _grid(v)
    want = _dense_inside(v, f, xs, ys, zs)
    got = _inside_grid(v, f, xs, ys, zs, block=block)
    assert got.shape == want.shape and want.sum() > 100
    np.testing.assert_array_equal(got, want)


def test_crown_memory_does_not_grow_with_the_triangle_count():
    """20k triangles: the dense method needed a 256 x nx x F bool array (~370 MB); now far below."""
    v, f = sphere_mesh([0, 0, 4], 2.0, subdivisions=5)
    assert len(f) == 20480
    tracemalloc.start()
    try:
        crown = crown_from_meshes([(v, f)])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 150e6
    inside = crown.values < 0
    centre = np.round((np.array([0, 0, 4]) - crown.origin) / crown.spacing).astype(int)
    assert inside[tuple(centre)] and not inside[0, 0, 0]
