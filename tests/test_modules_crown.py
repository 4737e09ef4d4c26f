"""Crown SDF, sphere tracing, attraction sampling and the per-step formulas (Eqs. 1-3)."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_server.modules.attract import sample_attraction_points
from arboretum_server.modules.crown import crown_from_meshes, crown_sdf
from arboretum_server.modules.pairing import choose_modules, pair_cost
from arboretum_server.modules.place import adjust_point, bias_direction
from arboretum_server.modules.shapes import box_mesh, sphere_mesh, tetrahedron_mesh, torus_mesh
from arboretum_server.modules.trace import ray_entry_exit, segments_stay_inside


@pytest.fixture(scope="module")
def sphere():
    return crown_from_meshes([sphere_mesh([0, 0, 5], 3)], resolution=48)


@pytest.fixture(scope="module")
def torus():
    return crown_from_meshes([torus_mesh([0, 0, 5], 2.5, 1.0)], resolution=48)


def test_sphere_sdf_matches_analytic(sphere, rng):
    p = rng.uniform([-4, -4, 1], [4, 4, 9], (2000, 3))
    true = np.linalg.norm(p - [0, 0, 5], axis=1) - 3
    err = np.abs(crown_sdf(sphere, p) - true)
    assert np.median(err) < 0.3 * sphere.spacing
    assert err.max() < 1.5 * sphere.spacing


def test_torus_hole_is_outside_and_tube_inside(torus):
    d = crown_sdf(torus, np.array([[0, 0, 5.0], [2.5, 0, 5], [0, -2.5, 5], [0, 0, 20]]))
    assert d[0] > 1.3 and d[1] < -0.8 and d[2] < -0.8 and d[3] > 10


def test_union_of_overlapping_meshes_and_disjoint_cubes():
    c = crown_from_meshes(
        [box_mesh([0, 0, 0], [2, 2, 2]), box_mesh([1, 1, 1], [3, 3, 3])], resolution=40
    )
    d = crown_sdf(c, np.array([[1.5, 1.5, 1.5], [0.5, 0.5, 0.5], [2.5, 2.5, 2.5], [0.5, 2.5, 0.5]]))
    assert (d[:3] < -0.3).all() and d[3] > 0.3


def test_tetrahedron_centroid_inside_apex_region_outside():
    c = crown_from_meshes([tetrahedron_mesh([0, 0, 0], 4.0)], resolution=40)
    d = crown_sdf(c, np.array([[0, 0, 0.0], [1.5, 1.5, 2.0]]))
    assert d[0] < -0.3 and d[1] > 0.3


def test_crown_needs_closed_meshes():
    with pytest.raises(InputError, match="crown"):
        crown_from_meshes([])
    v, f = box_mesh([0, 0, 0], [1, 1, 1])
    with pytest.raises(InputError, match="not closed"):
        crown_from_meshes([(v, f[:-1])])


def test_attraction_points_counts_and_placement(sphere):
    pts = sample_attraction_points(sphere, 500, 200, np.random.default_rng(3))
    assert pts.shape == (700, 3)
    d = crown_sdf(sphere, pts)
    assert (d[:500] < 0).all()
    assert np.abs(np.linalg.norm(pts[500:] - [0, 0, 5], axis=1) - 3).max() < 0.05
    again = sample_attraction_points(sphere, 500, 200, np.random.default_rng(3))
    assert np.array_equal(pts, again)


def test_sphere_tracing_rejects_paths_through_the_hole(torus):
    start = np.array([[2.5, 0, 5.0], [2.5, 0, 5.0], [0, 0, 5.0]])
    end = np.array([[-2.5, 0, 5.0], [-1.7678, 1.7678, 5.0], [0, 2.5, 5.0]])
    ok = segments_stay_inside(torus, start, end, tol=0.05)
    # across the hole: out; a 135-degree chord leaves the tube; from the hole: enters once
    assert list(ok) == [False, False, True]
    entry, exit_ = ray_entry_exit(torus, np.array([[0, 0, 5.0]]), np.array([[1.0, 0, 0]]), 10.0)
    assert abs(entry[0] - 1.5) < 0.1 and abs(exit_[0] - 3.5) < 0.1


def test_eq1_picks_scale_closest_to_one_within_constraints():
    size = np.array([1.0, 2.0])
    base_r = np.array([0.05, 0.1])
    # target 2 m, thick parent: module 1 at s=1 is exact
    m, s, ok = choose_modules(np.array([2.0]), np.array([0.2]), size, base_r, 0.5, 2.0)
    assert (m[0], s[0], ok[0]) == (1, 1.0, True)
    # thin parent (r_p = 0.06): module 1 capped at 0.6 by the radius ratio, module 0 at s = 1.2
    m, s, ok = choose_modules(np.array([2.0]), np.array([0.06]), size, base_r, 0.5, 2.0)
    assert m[0] == 0 and np.isclose(s[0], 1.2)
    # r_p / r_c below s_l for every module: infeasible
    _, _, ok = choose_modules(np.array([2.0]), np.array([0.02]), size, base_r, 0.5, 2.0)
    assert not ok[0]


def test_eq2_cost_blends_distance_and_reach():
    dt = np.array([[1.0, 3.0]])
    length = np.array([[1.0, 1.5]])
    sigma = pair_cost(dt, length, np.ones((1, 2), bool), C=2.0)
    lam1 = 1.0 / 3.0
    expect = lam1 * np.abs(length / dt - 1) + (1 - lam1) * dt / (dt + 2.0)
    assert np.allclose(sigma, expect)


def test_eq3_moves_branching_point_to_face_the_direction():
    p = np.array([[0.1, 0, 0.0]])
    n, t, r = np.array([[1.0, 0, 0]]), np.array([[0, 0, 1.0]]), np.array([0.1])
    v = np.array([[0, 1.0, 0.2]]) / np.linalg.norm([0, 1, 0.2])
    p_new, normal = adjust_point(p, n, t, r, v)
    assert np.allclose(p_new, [[0, 0.1, 0]], atol=1e-12) and np.allclose(
        normal, [[0, 1, 0]], atol=1e-12
    )


def test_direction_bias_clamps_angle():
    t = np.array([[0, 0, 1.0], [0, 0, 1.0]])
    v = np.array([[0.05, 0, 1.0], [0, 1.0, -1.0]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    out = bias_direction(
        v, t, np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.radians(15), np.radians(90), 1.0
    )
    ang = np.degrees(np.arccos(out @ [0, 0, 1.0]))
    assert np.allclose(ang, [15, 90])
    half = bias_direction(
        v, t, np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.radians(15), np.radians(90), 0.5
    )
    assert np.allclose(
        np.degrees(np.arccos(half @ [0, 0, 1.0])), [(15 + np.degrees(np.arctan(0.05))) / 2, 112.5]
    )
