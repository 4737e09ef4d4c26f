"""Point-in-hull by ray parity against a slow, obviously correct reference (generalised winding number)."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.grow.demo import icosphere
from arboretum_server.grow.hulls import build_index, inside, mesh_volume, sample_inside


def winding_number(verts: np.ndarray, faces: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(Q,) generalised winding number of points ``q`` (Q, 3) w.r.t. a closed mesh (slow reference)."""
    t = np.asarray(verts, float)[np.asarray(faces)]
    out = np.zeros(len(q))
    for i in range(0, len(q), 256):
        a, b, c = (t[None, :, k] - q[i:i + 256, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        num = np.einsum("qfi,qfi->qf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("qfi,qfi->qf", a, b) * lc + np.einsum("qfi,qfi->qf", a, c) * lb
               + np.einsum("qfi,qfi->qf", b, c) * la)
        out[i:i + 256] = (2 * np.arctan2(num, den)).sum(1) / (4 * np.pi)
    return out


def _hulls(rng):
    v, f = icosphere(2)
    blob = v * (1 + 0.3 * np.sin(3 * v[:, :1]) * np.cos(2 * v[:, 1:2]))  # non-convex, star-shaped
    box_v = np.array([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)], float) + 5
    box_f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return [(blob, f), (box_v, box_f)]


def test_inside_matches_winding_number(rng):
    hulls = _hulls(rng)
    index = build_index(hulls)
    for h, (v, f) in enumerate(hulls):
        lo, hi = v.min(0) - 0.2, v.max(0) + 0.2
        q = rng.uniform(lo, hi, (3000, 3))
        got = inside(index, q, np.full(len(q), h))
        ref = winding_number(v, f, q) > 0.5
        assert np.array_equal(got, ref)
        assert 300 < got.sum() < 2900


def test_points_of_one_hull_are_not_inside_another(rng):
    index = build_index(_hulls(rng))
    q = rng.uniform(-0.5, 0.5, (200, 3))
    assert inside(index, q, np.zeros(200, int)).all()
    assert not inside(index, q, np.ones(200, int)).any()


def test_grid_aligned_queries_on_a_box_are_exact(rng):
    """Rays through shared edges and vertices of an axis-aligned box are counted once."""
    (_, _), (v, f) = _hulls(rng)
    index = build_index([(v, f)])
    g = np.stack(np.meshgrid(*[np.linspace(4.05, 8.95, 50)] * 3), -1).reshape(-1, 3)
    g[:, :2] = np.round(g[:, :2] * 4) / 4  # many rays exactly through edges and vertices in xy
    on_face = (np.isin(g[:, 0], [5, 6]) | np.isin(g[:, 1], [5, 7])) & (g >= 5).all(1) & (g <= [6, 7, 8]).all(1)
    ref = (g > 5).all(1) & (g < [6, 7, 8]).all(1)
    got = inside(index, g, np.zeros(len(g), int))
    assert on_face.sum() > 100 and ref.sum() > 1000
    assert np.array_equal(got[~on_face], ref[~on_face])


def test_volume_and_rejection_sampling(rng):
    v, f = icosphere(3)
    assert mesh_volume(v, f) == pytest.approx(4 / 3 * np.pi, rel=0.02)
    pts, none = sample_inside(build_index([(v, f), (v + 5, f)]), np.array([500, 0]), rng)
    assert pts.shape == (500, 3) and none.shape == (0, 3)
    assert (winding_number(v, f, pts) > 0.5).all()
    assert abs(pts.mean(0)).max() < 0.1  # uniform, not biased to a side
