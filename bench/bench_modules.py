"""Controllable modular trees: growth time for a small and a large tree (median of 3).

The paper (16-core Xeon, Houdini) places 120 modules in 0.5 s and 4,600 in 2.4 s; the issue's targets on
this 2-core machine are 0.25 s and 1.2 s. Module preprocessing (skeletons, branching points) and the crown's
SDF are timed separately, as the paper treats them as inputs. Baseline: the first global step with every
attraction/branching pair sphere-traced up front (eager) against ours (lazy: best pair first).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from bench.harness import Row, median_time


def _scenes():
    from arboretum_library.geometry import make_transform
    from arboretum_server.modules.shapes import sphere_mesh, tetrahedron_mesh

    return {
        "small (tetrahedron crown)": ([tetrahedron_mesh([0, 0, 4.6], 6.5)], np.eye(4), {}, 0.25),
        # crown 18 m across = 18 lengths of a median branch module (1 m at s = 1); trunk 10 m, top at z = 10
        "large (sphere r=9 m, trunk x3, d_k=1/20)": (
            [sphere_mesh([0, 0, 12], 9)],
            make_transform(scale=3.0),
            {"kill_fraction": 0.05},
            1.2,
        ),
    }


def _eager_assign(attract, bp, radius, size, base_r, crown, C, o, tol):
    """Reference global step: trace all k pairs of every attraction point, then take the cheapest valid."""
    from scipy.spatial import cKDTree

    from arboretum_server.modules.pairing import choose_modules, pair_cost
    from arboretum_server.modules.trace import segments_stay_inside

    k = min(o.neighbours, len(bp))
    dt, j = cKDTree(bp).query(attract, k=k)
    dt, j = dt.reshape(len(attract), k), j.reshape(len(attract), k)
    m, s, feasible = choose_modules(
        dt, radius, size, base_r, o.scale_lower, o.scale_upper, gather=j
    )
    sigma = pair_cost(dt, size[m] * s, feasible, C)
    ok = segments_stay_inside(crown, bp[j.ravel()], np.repeat(attract, k, axis=0), tol).reshape(
        dt.shape
    )
    sigma = np.where(ok, sigma, np.inf)
    best = np.argmin(sigma, axis=1)
    return np.where(np.isfinite(sigma.min(axis=1)), j[np.arange(len(j)), best], -1)


def _global_step_rows(modules, prepared, crown, o) -> list[Row]:
    from arboretum_server.modules.attract import sample_attraction_points
    from arboretum_server.modules.branching import place_branch_points
    from arboretum_server.modules.pairing import assign_attraction

    attract = sample_attraction_points(crown, o.n_interior, o.n_surface, np.random.default_rng(1))
    trunk = int(modules.trunk_indices[0])
    bp = place_branch_points(prepared.branch_points[trunk], np.eye(4))
    axis = float(
        np.ptp(np.concatenate([modules.modules[trunk].vertices, crown.bounds]), axis=0).max()
    )
    C, tol = o.saturation_fraction * axis, o.crown_tolerance_fraction * axis
    args = (attract, bp.position, bp.radius, prepared.size, prepared.base_radius, crown)

    def lazy():
        kw = {"k": o.neighbours, "C": C, "s_lo": o.scale_lower, "s_hi": o.scale_upper, "tol": tol}
        return assign_attraction(*args, **kw)

    def eager():
        return _eager_assign(*args, C, o, tol)

    same = bool(np.array_equal(lazy(), eager()))
    t_lazy, t_eager = median_time(lazy, runs=3), median_time(eager, runs=3)
    return [
        Row(
            "first global step, 7,000 attraction points x trunk points",
            t_lazy,
            runs=3,
            baseline="eager sphere tracing of all pairs",
            ratio=t_lazy / t_eager,
            note=f"same assignment as the baseline: {same}",
        )
    ]


def run() -> list[Row]:
    from arboretum_server.modules.crown import crown_from_meshes
    from arboretum_server.modules.grow import grow_modular_tree, prepare_modules
    from arboretum_server.modules.options import ModularTreeOptions
    from arboretum_server.modules.procedural import make_default_module_set

    t0 = time.perf_counter()
    modules = make_default_module_set(np.random.default_rng(7))
    rows = [
        Row(
            "default module set: sweep + Appendix A skeletons (25 modules)",
            time.perf_counter() - t0,
        )
    ]
    for name, (meshes, T, extra, target) in _scenes().items():
        o = ModularTreeOptions(**extra)
        prepared = prepare_modules(modules, o)
        t0 = time.perf_counter()
        crown = crown_from_meshes(meshes, o.sdf_resolution)
        t_crown = time.perf_counter() - t0
        times, cpu, trees = [], [], []
        for seed in (1, 2, 3):
            t0, c0 = time.perf_counter(), time.process_time()
            trees.append(
                grow_modular_tree(
                    modules,
                    crown,
                    o,
                    np.random.default_rng(seed),
                    T_world_trunk=T,
                    prepared=prepared,
                )
            )
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        counts = [t.stats.modules_placed for t in trees]
        rows.append(
            Row(
                f"grow {name}",
                statistics.median(times),
                target=target,
                runs=3,
                note=f"modules placed {counts}; reached {[round(t.stats.reached_fraction, 3) for t in trees]}; "
                f"crown SDF {t_crown:.2f} s (not included); CPU time {statistics.median(cpu):.3f} s",
                extra={"modules": counts, "violations": [t.stats.violations for t in trees]},
            )
        )
        if name.startswith("large"):
            rows += _global_step_rows(modules, prepared, crown, o)
    return rows
