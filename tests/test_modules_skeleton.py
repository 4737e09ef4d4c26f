"""Module skeleton curves (Appendix A), module meshes and their I/O."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.geometry import point_polyline_distance, zup_to_yup
from arboretum_server.modules._tube import Limb, sweep_limbs
from arboretum_server.modules.meshio import load_mesh, save_obj
from arboretum_server.modules.moduleset import load_module_set, save_module_set
from arboretum_server.modules.procedural import make_default_module_set
from arboretum_server.modules.skeleton import extract_skeleton

R_STEM, R_ARM = 0.1, 0.07
FORK = np.array([0.0, 0.0, 1.0])


def _y_mesh():
    """A Y: a 1 m stem of radius 0.1 and two 0.8 m arms of radius 0.07 leaving its top at 45 degrees."""
    z = np.linspace(0, 1, 11)
    stem = Limb(np.stack([0 * z, 0 * z, z], 1), np.full(11, R_STEM), -1)
    axes = [np.stack([0 * z, 0 * z, z], 1)]
    limbs = [stem]
    for d in ([1.0, 0.0, 1.0], [-1.0, 0.3, 1.0]):
        d = np.array(d) / np.linalg.norm(d)
        pts = FORK + np.linspace(0, 0.8, 9)[:, None] * d
        limbs.append(Limb(pts, np.full(9, R_ARM), 0))
        axes.append(pts)
    v, f = sweep_limbs(limbs, sides=10)
    return v, f, axes


def test_y_skeleton_has_one_fork_with_two_children():
    v, f, _ = _y_mesh()
    sk = extract_skeleton(v, f)
    assert list(sk.spline_parent) == [-1, 0, 0]
    assert len(sk.tips) == 2
    assert set(sk.spline[sk.tips]) == {1, 2}


def test_y_skeleton_points_near_axes_with_true_radii():
    v, f, axes = _y_mesh()
    sk = extract_skeleton(v, f)
    # away from the crotch (the junction hull spans ~2.5 stem radii around the fork) and the capped tips
    away = np.linalg.norm(sk.points - FORK, axis=1) > 3 * R_STEM
    away[sk.tips] = False
    away[0] = False
    true_r = np.where(sk.spline == 0, R_STEM, R_ARM)
    arms = np.array([[point_polyline_distance(p[None], a)[0] for a in axes[1:]] for p in sk.points])
    dist = np.where(
        sk.spline == 0,
        [point_polyline_distance(p[None], axes[0])[0] for p in sk.points],
        arms.min(1),
    )
    assert away.sum() >= 30
    assert np.all(dist[away] < 0.3 * true_r[away])
    assert np.all(np.abs(sk.radius[away] - true_r[away]) < 0.2 * true_r[away])


def test_tangents_are_unit_and_point_away_from_base():
    v, f, _ = _y_mesh()
    sk = extract_skeleton(v, f)
    assert np.allclose(np.linalg.norm(sk.tangent, axis=1), 1.0)
    assert np.allclose(sk.base_direction, [0, 0, 1], atol=0.05)
    assert np.linalg.norm(sk.base) < 0.01


def test_default_module_set_is_varied_and_closed():
    import trimesh

    ms = make_default_module_set(np.random.default_rng(7))
    assert len(ms.branch_indices) >= 8 and len(ms.trunk_indices) == 2
    forks = [len(m.skeleton.tips) for m in ms.modules if not m.is_trunk]
    assert min(forks) == 1 and max(forks) >= 3
    assert np.ptp([m.size for m in ms.modules if not m.is_trunk]) > 0.5
    for m in ms.modules:
        mesh = trimesh.Trimesh(m.vertices, m.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, m.name
        assert np.allclose(m.skeleton.points[0], 0, atol=1e-9)


def test_obj_and_glb_round_trip(tmp_path):
    import trimesh

    v, f, _ = _y_mesh()
    save_obj(tmp_path / "y.obj", v, f)
    v2, f2 = load_mesh(tmp_path / "y.obj")
    assert len(f2) == len(f) and np.allclose(np.sort(v2[:, 2]), np.sort(v[:, 2]), atol=1e-4)
    trimesh.Trimesh(zup_to_yup(v), f, process=False).export(tmp_path / "y.glb")
    v3, _ = load_mesh(tmp_path / "y.glb")
    assert np.allclose(v3.min(axis=0), v.min(axis=0), atol=1e-5)
    assert np.allclose(v3.max(axis=0), v.max(axis=0), atol=1e-5)


def test_module_set_save_load(tmp_path):
    ms = make_default_module_set(np.random.default_rng(7)).subset(
        ["trunk_00_straight", "branch_02_fork"]
    )
    save_module_set(ms, tmp_path)
    back = load_module_set(tmp_path)
    assert [m.name for m in back.modules] == ["branch_02_fork", "trunk_00_straight"]
    assert abs(back.modules[0].size - ms.modules[1].size) < 0.02


def test_bad_inputs_raise_input_error(tmp_path):
    with pytest.raises(InputError, match="unsupported"):
        load_mesh(tmp_path / "x.stl")
    with pytest.raises(InputError, match="no such file"):
        load_mesh(tmp_path / "x.obj")
    with pytest.raises(InputError, match="no .obj"):
        load_module_set(tmp_path)


def test_bundled_default_set_matches_the_generator():
    from arboretum_library.assets import asset_path

    bundled = load_module_set(asset_path("modules", "default"))
    fresh = make_default_module_set(np.random.default_rng(7))
    assert sorted(m.name for m in bundled.modules) == sorted(m.name for m in fresh.modules)
    by_name = {m.name: m for m in fresh.modules}
    for m in bundled.modules:
        assert abs(m.size - by_name[m.name].size) < 0.02 * m.size, (
            m.name
        )  # base plane re-detected on load
        assert len(m.skeleton.tips) == len(by_name[m.name].skeleton.tips), m.name


def test_make_module_normalises_a_moved_mesh():
    from arboretum_library.geometry import axis_angle_matrix
    from arboretum_server.modules.moduleset import make_module

    v, f, _ = _y_mesh()
    ref = make_module("y", v, f)
    R = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), np.radians(40))  # keeps the base plane
    m = make_module("y", v @ R.T + [5.0, -2.0, 3.0], f)
    assert np.allclose(m.skeleton.points[0], 0, atol=1e-9)
    assert np.allclose(
        np.linalg.norm(m.vertices, axis=1), np.linalg.norm(ref.vertices, axis=1), atol=1e-6
    )
    assert abs(m.size - ref.size) < 1e-6
