"""Modular tree growth (Takikawa et al. 2025): constraints on every module, filling non-convex crowns."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.geometry import resample_polyline
from arboretum_server.modules.crown import crown_from_meshes, crown_sdf
from arboretum_server.modules.grow import grow_modular_tree, prepare_modules
from arboretum_server.modules.options import ModularTreeOptions
from arboretum_server.modules.procedural import make_default_module_set
from arboretum_server.modules.shapes import box_mesh, sphere_mesh, tetrahedron_mesh, torus_mesh

OPT = ModularTreeOptions()
CROWNS = {
    "sphere": [sphere_mesh([0, 0, 6], 3)],
    # around the trunk, which stands in the hole: the "trunk outside the crown" case
    "torus": [torus_mesh([0, 0, 4.5], 2.5, 1.0)],
    "tetrahedron": [tetrahedron_mesh([0, 0, 4.6], 6.5)],
    "cubes": [
        box_mesh([1.0, -0.8, 2.0], [2.6, 0.8, 3.6]),
        box_mesh([-2.6, -0.8, 2.6], [-1.0, 0.8, 4.2]),
        box_mesh([-0.8, 1.0, 3.2], [0.8, 2.6, 4.8]),
        box_mesh([-0.8, -0.8, 4.6], [0.8, 0.8, 6.2]),
    ],
}


@pytest.fixture(scope="module")
def modules():
    return make_default_module_set(np.random.default_rng(7))


@pytest.fixture(scope="module")
def prepared(modules):
    return prepare_modules(modules, OPT)


@pytest.fixture(scope="module")
def crowns():
    return {name: crown_from_meshes(m) for name, m in CROWNS.items()}


@pytest.fixture(scope="module")
def trees(modules, prepared, crowns):
    return {
        name: grow_modular_tree(modules, c, OPT, np.random.default_rng(1), prepared=prepared)
        for name, c in crowns.items()
    }


def _tolerance(tree, crown, modules) -> float:
    box = np.concatenate([modules.modules[int(tree.module[0])].vertices, crown.bounds])
    return OPT.crown_tolerance_fraction * float(np.ptp(box, axis=0).max())


@pytest.mark.parametrize("name", list(CROWNS))
def test_scale_radius_and_angle_constraints_hold(trees, modules, name):
    tree = trees[name]
    assert tree.stats.modules_placed > 50
    A = tree.T_world_module[1:, :3, :3]
    s = np.cbrt(np.linalg.det(A))
    # uniform scale: A / s is a rotation
    R = A / s[:, None, None]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.allclose(s, tree.scale[1:])
    assert (s >= OPT.scale_lower - 1e-9).all() and (s <= OPT.scale_upper + 1e-9).all()
    base_r = np.array([modules.modules[m].skeleton.base_radius for m in tree.module[1:]])
    assert (base_r * s <= tree.parent_radius[1:] * (1 + 1e-9)).all()
    v = R[:, :, 2]
    angle = np.degrees(np.arccos(np.clip((v * tree.parent_tangent[1:]).sum(1), -1, 1)))
    assert (angle >= OPT.angle_lower_deg - 1e-6).all() and (
        angle <= OPT.angle_upper_deg + 1e-6
    ).all()
    assert tree.stats.violations == {"scale": 0, "radius": 0, "angle": 0, "crown": 0}


@pytest.mark.parametrize("name", list(CROWNS))
def test_parent_radius_comes_from_the_parent_skeleton(trees, modules, name):
    tree = trees[name]
    for i in range(1, len(tree.module), 5):
        p = tree.parent[i]
        T = tree.T_world_module[p]
        sk = modules.modules[tree.module[p]].skeleton
        world = sk.points @ T[:3, :3].T + T[:3, 3]
        size = modules.modules[tree.module[p]].size * tree.scale[p]
        near = (
            np.linalg.norm(world - tree.T_world_module[i][:3, 3], axis=1)
            < OPT.spacing_fraction * size + 2 * tree.parent_radius[i]
        )
        r = sk.radius[near] * tree.scale[p]
        assert near.any() and r.min() * (1 - 1e-9) <= tree.parent_radius[i] <= r.max() * (1 + 1e-9)


@pytest.mark.parametrize("name", list(CROWNS))
def test_no_branch_outside_the_crown(trees, crowns, modules, name):
    tree, crown = trees[name], crowns[name]
    tol = _tolerance(tree, crown, modules)
    worst = -np.inf
    for i in range(1, len(tree.module)):
        sk = modules.modules[tree.module[i]].skeleton
        T = tree.T_world_module[i]
        pts = np.concatenate(
            [resample_polyline(sk.points[sk.spline == s], 30) for s in np.unique(sk.spline)]
        )
        world = pts @ T[:3, :3].T + T[:3, 3]
        past_entry = (world - T[:3, 3]) @ tree.direction[i] >= tree.entry[i]
        worst = max(worst, crown_sdf(crown, world[past_entry]).max(initial=-np.inf))
    assert worst <= tol


@pytest.mark.parametrize("name", ["torus", "tetrahedron", "cubes", "sphere"])
def test_non_convex_crowns_are_filled(trees, name):
    assert trees[name].stats.reached_fraction >= 0.85
    assert trees[name].stats.types_used >= 6


def test_tree_structure_is_consistent(trees):
    tree = trees["sphere"]
    assert tree.parent[0] == -1 and tree.depth[0] == 0
    assert (tree.parent[1:] < np.arange(1, len(tree.parent))).all()
    # depth is the layer; unused branching points of older layers may still carry later branches
    assert (tree.depth[1:] > tree.depth[tree.parent[1:]]).all()
    assert set(np.unique(tree.depth)) == set(range(tree.depth.max() + 1))
    assert tree.stats.iterations == tree.depth.max()


@pytest.mark.parametrize(
    "names",
    [
        ["trunk_00_straight", "branch_02_fork"],
        ["trunk_00_straight", "branch_11_thick_single", "branch_06_multi_fork"],
    ],
)
def test_one_or_two_module_types_still_give_a_tree(modules, crowns, names):
    sub = modules.subset(names)
    tree = grow_modular_tree(sub, crowns["tetrahedron"], OPT, np.random.default_rng(1))
    assert tree.stats.types_used == len(names)
    assert tree.stats.modules_placed > 50 and tree.stats.reached_fraction > 0.85
    assert sum(tree.stats.violations.values()) == 0


def test_same_seed_same_tree_other_seed_other_tree(modules, prepared, crowns):
    a = grow_modular_tree(
        modules, crowns["tetrahedron"], OPT, np.random.default_rng(5), prepared=prepared
    )
    b = grow_modular_tree(
        modules, crowns["tetrahedron"], OPT, np.random.default_rng(5), prepared=prepared
    )
    c = grow_modular_tree(
        modules, crowns["tetrahedron"], OPT, np.random.default_rng(6), prepared=prepared
    )
    assert np.array_equal(a.module, b.module) and np.array_equal(a.T_world_module, b.T_world_module)
    assert np.array_equal(a.parent, b.parent)
    assert len(a.module) != len(c.module) or not np.allclose(a.T_world_module, c.T_world_module)


def test_bias_off_lets_angles_leave_the_range(modules, prepared, crowns):
    opt = ModularTreeOptions(direction_bias=0.0)
    tree = grow_modular_tree(
        modules,
        crowns["sphere"],
        opt,
        np.random.default_rng(1),
        prepared=prepare_modules(modules, opt),
    )
    ang = np.degrees(tree.branch_angle[1:])
    assert ((ang < 15) | (ang > 90)).any()


def test_bad_scale_bounds_raise(modules, crowns):
    with pytest.raises(InputError, match="s_l"):
        grow_modular_tree(
            modules,
            crowns["sphere"],
            ModularTreeOptions(scale_lower=2.0, scale_upper=1.0),
            np.random.default_rng(1),
        )


def test_reached_means_within_kill_distance_of_a_branch(trees, crowns, modules):
    from scipy.spatial import cKDTree

    tree, crown = trees["tetrahedron"], crowns["tetrahedron"]
    box = np.concatenate([modules.modules[int(tree.module[0])].vertices, crown.bounds])
    d_kill = OPT.kill_fraction * float(np.ptp(box, axis=0).max())
    pts = [
        modules.modules[m].skeleton.points @ T[:3, :3].T + T[:3, 3]
        for m, T in zip(tree.module, tree.T_world_module)
    ]
    d, _ = cKDTree(np.concatenate(pts)).query(tree.attraction_points)
    assert (d[tree.reached] <= d_kill + 1e-9).all()
    assert (d[~tree.reached] > d_kill - 1e-9).all()
    assert np.isclose(tree.stats.reached_fraction, tree.reached.mean())


def test_trunk_in_the_torus_hole_grows_across_the_gap(trees, modules, prepared, crowns):
    tree = trees["torus"]
    first = tree.depth == 1
    assert first.sum() >= 3 and (tree.entry[first] > 0).all()
    forced = ModularTreeOptions(prune_trunk_outside=True)
    bare = grow_modular_tree(
        modules, crowns["torus"], forced, np.random.default_rng(1), prepared=prepared
    )
    assert bare.stats.modules_placed == 1 and bare.stats.reached_fraction < 0.05



@pytest.mark.slow
def test_large_crown_reaches_the_papers_module_count(modules):
    """The benchmark's large scene (bench/bench_modules.py): sphere r = 9 m, trunk x3, d_k = 1/20.

    The paper's most complex tree has 4,600 modules; ours has >= 4,600 (seed 2), reaches >= 85 % of the
    attraction points, and every constraint holds, re-checked here as for the four small crowns.
    """
    from arboretum_library.geometry import make_transform

    opt = ModularTreeOptions(kill_fraction=0.05)
    crown = crown_from_meshes([sphere_mesh([0, 0, 12], 9)])
    T0 = make_transform(scale=3.0)
    tree = grow_modular_tree(modules, crown, opt, np.random.default_rng(2), T_world_trunk=T0)
    assert tree.stats.modules_placed >= 4600 and tree.stats.reached_fraction >= 0.85
    assert tree.stats.violations == {"scale": 0, "radius": 0, "angle": 0, "crown": 0}
    A = tree.T_world_module[1:, :3, :3]
    s = np.cbrt(np.linalg.det(A))
    assert (s >= opt.scale_lower - 1e-9).all() and (s <= opt.scale_upper + 1e-9).all()
    base_r = np.array([modules.modules[m].skeleton.base_radius for m in tree.module[1:]])
    assert (base_r * s <= tree.parent_radius[1:] * (1 + 1e-9)).all()
    v = A[:, :, 2] / s[:, None]
    angle = np.degrees(np.arccos(np.clip((v * tree.parent_tangent[1:]).sum(1), -1, 1)))
    assert (angle >= opt.angle_lower_deg - 1e-6).all() and (angle <= opt.angle_upper_deg + 1e-6).all()
    trunk = modules.modules[int(tree.module[0])].vertices @ T0[:3, :3].T + T0[:3, 3]
    tol = opt.crown_tolerance_fraction * float(np.ptp(np.concatenate([trunk, crown.bounds]), axis=0).max())
    worst = -np.inf
    for i in range(1, len(tree.module)):
        sk, T = modules.modules[tree.module[i]].skeleton, tree.T_world_module[i]
        pts = np.concatenate(
            [resample_polyline(sk.points[sk.spline == k], 30) for k in np.unique(sk.spline)]
        )
        world = pts @ T[:3, :3].T + T[:3, 3]
        past_entry = (world - T[:3, 3]) @ tree.direction[i] >= tree.entry[i]
        worst = max(worst, crown_sdf(crown, world[past_entry]).max(initial=-np.inf))
    assert worst <= tol


def _choose_modules_reference(target, parent_radius, size, base_radius, s_lo, s_hi, gather):
    """The numpy running argmin over modules (float32) that the numba kernel replaced."""
    ratio = parent_radius[None, :] / base_radius[:, None]
    cap = np.where(ratio >= s_lo, np.minimum(ratio, s_hi), -1e9).astype(np.float32)
    t32, inv = target.astype(np.float32), (1.0 / size).astype(np.float32)
    best = np.zeros(target.shape, dtype=np.int64)
    best_err = np.full(target.shape, np.inf, dtype=np.float32)
    for m in range(len(size)):
        err = np.abs(np.minimum(np.maximum(t32 * inv[m], np.float32(s_lo)), cap[m][gather]) - 1)
        best[err < best_err] = m
        best_err = np.minimum(best_err, err)
    cap_best = cap[best, gather]
    pick = np.minimum(np.maximum(t32 * inv[best], np.float32(s_lo)), cap_best)
    return best, pick.astype(np.float64), cap_best >= s_lo


def test_eq1_kernel_equals_the_numpy_running_argmin():
    from arboretum_server.modules.pairing import choose_modules

    rng = np.random.default_rng(5)
    size = np.concatenate([rng.uniform(0.3, 2.0, 20), [1.0, 1.0, 0.5]])  # repeated sizes: ties
    base_r = np.concatenate([rng.uniform(0.01, 0.05, 20), [0.02, 0.02, 0.02]])
    radius = np.concatenate([rng.uniform(0.0, 0.1, 3000), np.zeros(100)])  # some thin: infeasible
    gather = rng.integers(0, len(radius), (700, 25))
    target = rng.uniform(0.0, 5.0, gather.shape)
    target[:5] = 1.0  # exact ties between the equal modules
    got = choose_modules(target, radius, size, base_r, 0.5, 2.0, gather=gather)
    want = _choose_modules_reference(target, radius, size, base_r, 0.5, 2.0, gather)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    assert 0 < want[2].mean() < 1 and len(np.unique(want[0])) > 10


def test_every_part_of_a_disjoint_crown_is_reached(crowns):
    """The top cube sits over the trunk's tip, reachable only from there; modules that stop short of a
    crown part (their branching points would all be pruned) are rejected, and attraction points whose
    25 nearest branching points sit in other parts are paired among their 100 nearest. Before, with the
    bundled module set (the docs' picture), the top cube kept 98 % of its attraction points."""
    from arboretum_library.assets import asset_path
    from arboretum_server.modules.moduleset import load_module_set

    bundled = load_module_set(asset_path("modules", "default"))
    tree = grow_modular_tree(bundled, crowns["cubes"], OPT, np.random.default_rng(1))
    for lo, hi in ([1.0, -0.8, 2.0], [2.6, 0.8, 3.6]), ([-0.8, -0.8, 4.6], [0.8, 0.8, 6.2]):
        inside = ((tree.attraction_points >= lo) & (tree.attraction_points <= hi)).all(axis=1)
        assert inside.sum() > 500 and tree.reached[inside].mean() >= 0.95
