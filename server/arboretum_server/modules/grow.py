"""Controllable modular trees (Takikawa et al., GI 2025, Sec. 4): grow a tree layer by layer from a trunk.

Each iteration: a global step pairs the live attraction points with branching points (pairing.py, Eqs.
1-2, sphere-traced crown check); a local step places one branch module per chosen branching point
(place.py, Eq. 3, direction bias, final Eq. 1); new branching points are sampled on the new modules,
pruned outside the crown and culled at random; attraction points within d_k of a new branch are pruned.
Stops when no attraction point is left, no branch is placed, or after ``max_iterations``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from arboretum_library.errors import InputError
from arboretum_library.geometry import resample_polyline

from .attract import sample_attraction_points
from .branching import BranchPoints, module_branch_points, place_branch_points
from .constraints import count_violations
from .crown import Crown, crown_sdf
from .moduleset import ModuleSet
from .options import ModularTreeOptions
from .pairing import assign_attraction
from .place import local_step
from .tree import ModularTree, ModularTreeStats


@dataclass
class _Pool:
    """Unused branching points (world) and the instance each lies on.

    ``data`` (N, 10) float64 packs position (3), normal (3), tangent (3) and radius (1) per point, so a
    layer's removal and addition copy one array, not four.
    """

    data: np.ndarray
    owner: np.ndarray

    @staticmethod
    def of(p: BranchPoints, owner: np.ndarray) -> _Pool:
        return _Pool(np.column_stack([p.position, p.normal, p.tangent, p.radius]), owner)

    @property
    def points(self) -> BranchPoints:
        d = self.data
        return BranchPoints(d[:, 0:3], d[:, 3:6], d[:, 6:9], d[:, 9])

    def take(self, keep: np.ndarray) -> _Pool:
        return _Pool(self.data[keep], self.owner[keep])

    def add(self, other: _Pool) -> _Pool:
        return _Pool(np.concatenate([self.data, other.data]), np.concatenate([self.owner, other.owner]))


def _skeleton_samples(modules: ModuleSet, idx: np.ndarray, n: int = 30) -> np.ndarray:
    """(M, S, 3) skeleton samples per branch module: every spline resampled, padded to one length."""
    out = []
    for i in idx:
        sk = modules.modules[i].skeleton
        parts = [resample_polyline(sk.points[sk.spline == s], n) for s in np.unique(sk.spline)]
        out.append(np.concatenate([sk.points, *parts]))  # the curve's own points and dense samples
    width = max(len(o) for o in out)
    return np.stack([np.concatenate([o, np.repeat(o[-1:], width - len(o), axis=0)]) for o in out])


@dataclass(frozen=True)
class PreparedModules:
    """Per-module data the growth reuses (Sec. 4.2 preprocessing), for one module set and options."""

    branches: np.ndarray
    """(M,) int indices of the branch modules in the module set."""
    size: np.ndarray
    """(M,) float64 size(M) of each branch module (metres at scale 1)."""
    base_radius: np.ndarray
    """(M,) float64 r_c of each branch module at its base."""
    skeleton: np.ndarray
    """(M, S, 3) float64 skeleton samples of each branch module (module frame)."""
    branch_points: dict
    """module-set index -> BranchPoints in the module frame (trunks and branches)."""


def prepare_modules(modules: ModuleSet, options: ModularTreeOptions) -> PreparedModules:
    """Sizes, base radii, skeleton samples and branching points of every module (done once per set)."""
    o = options
    branches = modules.branch_indices
    if len(branches) == 0:
        raise InputError("module set: has no branch modules")
    bp = {
        int(i): module_branch_points(
            m, o.spacing_fraction, o.junctions, o.junction_angle_deg, o.base_clearance
        )
        for i, m in enumerate(modules.modules)
    }
    return PreparedModules(
        branches,
        np.array([modules.modules[i].size for i in branches]),
        np.array([modules.modules[i].skeleton.base_radius for i in branches]),
        _skeleton_samples(modules, branches),
        bp,
    )


def _new_points(bp: BranchPoints, crown: Crown, keep_outside: bool, cull: float, rng) -> np.ndarray:
    """Indices of branching points kept: inside the crown (unless ``keep_outside``), survived the cull."""
    keep = (
        np.ones(len(bp.radius), dtype=bool) if keep_outside else crown_sdf(crown, bp.position) <= 0
    )
    return np.flatnonzero(keep & (rng.random(len(keep)) >= cull))


def grow_modular_tree(
    modules: ModuleSet,
    crown: Crown,
    options: ModularTreeOptions,
    rng: np.random.Generator,
    trunk: int | None = None,
    T_world_trunk: np.ndarray | None = None,
    prepared: PreparedModules | None = None,
) -> ModularTree:
    """Grow a modular tree in ``crown`` from a trunk of ``modules`` (first trunk, or module ``trunk``).

    ``prepared`` (from ``prepare_modules`` with the same set and options) skips the per-module work.
    """
    o = options
    if not 0 < o.scale_lower <= o.scale_upper:
        raise InputError(f"options: need 0 < s_l <= s_u, got {o.scale_lower}, {o.scale_upper}")
    pm = prepared or prepare_modules(modules, o)
    trunks = modules.trunk_indices
    trunk = int(
        trunks[0] if trunk is None and len(trunks) else (pm.branches[0] if trunk is None else trunk)
    )
    T0 = np.eye(4) if T_world_trunk is None else np.asarray(T_world_trunk, dtype=np.float64)
    g = _start(modules, crown, o, rng, pm, trunk, T0)
    iterations = 0
    for it in range(o.max_iterations):
        if not g.alive.any() or len(g.pool.owner) == 0 or not _layer(g, modules, crown, o, rng, pm, it):
            break
        iterations = it + 1
    return _finish(g.inst, modules, crown, o, g.attract, g.alive, iterations, g.tol)


@dataclass
class _Growth:
    """The state of a growing tree between layers."""

    inst: dict
    """Per-instance lists (module, T, parent, depth, scale, r_p, r_c, t_p, dir, entry)."""
    pool: _Pool
    attract: np.ndarray
    """(A, 3) attraction points."""
    alive: np.ndarray
    """(A,) bool: not yet reached (farther than d_k from every branch)."""
    C: float
    d_kill: float
    tol: float


def _start(modules, crown, o, rng, pm, trunk: int, T0: np.ndarray) -> _Growth:
    """The trunk placed by ``T0``, its branching points and the attraction points it has not reached."""
    box = np.concatenate([modules.modules[trunk].vertices @ T0[:3, :3].T + T0[:3, 3], crown.bounds])
    axis = float(np.ptp(box, axis=0).max())
    attract = sample_attraction_points(crown, o.n_interior, o.n_surface, rng)
    r_c = modules.modules[trunk].skeleton.base_radius * float(np.cbrt(np.linalg.det(T0[:3, :3])))
    inst = {"module": [trunk], "T": [T0], "parent": [-1], "depth": [0], "scale": [1.0], "r_p": [np.nan],
            "r_c": [r_c], "t_p": [np.full(3, np.nan)], "dir": [T0[:3, 2] / np.linalg.norm(T0[:3, 2])],
            "entry": [0.0]}
    pool = _trunk_pool(pm.branch_points[trunk], T0, crown, o, rng)
    d_kill = o.kill_fraction * axis
    alive = _far_from(attract, modules.modules[trunk].skeleton.points @ T0[:3, :3].T + T0[:3, 3], d_kill)
    return _Growth(inst, pool, attract, alive, o.saturation_fraction * axis, d_kill,
                   o.crown_tolerance_fraction * axis)


def _layer(g: _Growth, modules, crown, o, rng, pm, it: int) -> bool:
    """One layer (global step, local step, new branching points, kill); False if nothing was placed."""
    live = np.flatnonzero(g.alive)
    points = g.pool.points
    assign = assign_attraction(g.attract[live], np.ascontiguousarray(points.position), points.radius, pm.size,
                               pm.base_radius, crown, k=o.neighbours, C=g.C, s_lo=o.scale_lower,
                               s_hi=o.scale_upper, tol=g.tol)
    if not (assign >= 0).any():
        return False
    pl = local_step(assign, g.attract[live], points, crown, pm.size, pm.base_radius, pm.skeleton,
                    o.surface_weight * o.surface_weight_decay**it,
                    (np.radians(o.angle_lower_deg), np.radians(o.angle_upper_deg)), o.direction_bias,
                    o.scale_lower, o.scale_upper, g.tol, rng)
    if len(pl.module) == 0:
        return False
    first = len(g.inst["module"])
    grown = _record(g.inst, pl, g.pool, pm.branches, pm.base_radius, it + 1)
    g.pool = _next_pool(g.pool, pl.branch_point, grown, first, pm, crown, o, rng)
    new_sk, _ = _placed([modules.modules[m].skeleton.points for m, _ in grown], grown)
    g.alive[live] = _far_from(g.attract[live], new_sk, g.d_kill)
    return True


def _trunk_pool(
    local: BranchPoints, T0: np.ndarray, crown: Crown, o: ModularTreeOptions, rng
) -> _Pool:
    """Branching points of the trunk; outside-crown ones are kept when the trunk never enters (Sec. 4.3)."""
    tbp = place_branch_points(local, T0)
    inside = crown_sdf(crown, tbp.position) <= 0
    prune = o.prune_trunk_outside if o.prune_trunk_outside is not None else bool(inside.any())
    keep = _new_points(tbp, crown, not prune, o.cull_fraction, rng)
    return _Pool.of(tbp, np.zeros(len(inside), dtype=np.int64)).take(keep)


def _next_pool(
    pool: _Pool,
    used_ids: np.ndarray,
    grown: list,
    first: int,
    pm: PreparedModules,
    crown: Crown,
    o: ModularTreeOptions,
    rng,
) -> _Pool:
    """Unused points of ``pool`` plus the pruned, culled branching points of the ``grown`` instances."""
    used = np.zeros(len(pool.owner), dtype=bool)
    used[used_ids] = True
    pool = pool.take(~used)
    local = [pm.branch_points[m] for m, _ in grown]
    position, k = _placed([b.position for b in local], grown)
    scale = np.cbrt(np.linalg.det(np.stack([T[:3, :3] for _, T in grown])))
    normal, _ = _placed([b.normal for b in local], grown, 1.0 / scale)
    tangent, _ = _placed([b.tangent for b in local], grown, 1.0 / scale)
    new = BranchPoints(position, normal, tangent, np.concatenate([b.radius for b in local]) * scale[k])
    owner = first + k
    keep = _new_points(new, crown, False, o.cull_fraction, rng)
    return pool.add(_Pool.of(new, owner).take(keep))


def _placed(local: list, grown: list, factor: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``local[k]`` (n_k, 3) moved by the k-th transform of ``grown`` [(module, T (4, 4))], all at once.

    Positions (``factor`` None) get the whole similarity; directions get the linear part times ``factor``
    (K,) (1 / scale: a rotation). Returns the stacked (sum n_k, 3) rows and the (sum n_k,) instance k.
    """
    T = np.stack([t for _, t in grown])
    k = np.repeat(np.arange(len(local)), [len(a) for a in local])
    A = T[:, :3, :3] if factor is None else T[:, :3, :3] * factor[:, None, None]
    out = np.einsum("nij,nj->ni", A[k], np.concatenate(local))
    return (out + T[k, :3, 3] if factor is None else out), k


def _far_from(points: np.ndarray, branch: np.ndarray, d_kill: float) -> np.ndarray:
    """(N,) bool: points farther than ``d_kill`` from every point of ``branch`` (M, 3)."""
    d, _ = cKDTree(branch).query(points, distance_upper_bound=d_kill)
    return ~np.isfinite(d)


def _record(
    inst: dict, pl, pool: _Pool, branches: np.ndarray, base_r: np.ndarray, depth: int
) -> list:
    """Append the placements to ``inst``; returns [(module set index, T_world_module)]."""
    out, pts = [], pool.points
    for k in range(len(pl.module)):
        m = int(branches[pl.module[k]])
        T = np.eye(4)
        T[:3, :3] = pl.scale[k] * pl.rotation[k]
        T[:3, 3] = pl.position[k]
        b = pl.branch_point[k]
        for key, val in (
            ("module", m),
            ("T", T),
            ("parent", int(pool.owner[b])),
            ("depth", depth),
            ("scale", float(pl.scale[k])),
            ("r_p", float(pts.radius[b])),
            ("r_c", float(base_r[pl.module[k]] * pl.scale[k])),
            ("t_p", pts.tangent[b].copy()),
            ("dir", pl.direction[k]),
            ("entry", float(pl.entry[k])),
        ):
            inst[key].append(val)
        out.append((m, T))
    return out


def _finish(inst, modules, crown, o, attract, alive, iterations, tol) -> ModularTree:
    module = np.asarray(inst["module"], dtype=np.int32)
    T = np.asarray(inst["T"])
    t_p, direction = np.asarray(inst["t_p"]), np.asarray(inst["dir"])
    angle = (
        np.arccos(np.clip((t_p * direction).sum(axis=1), -1.0, 1.0)) if len(module) else np.zeros(0)
    )
    args = (
        module,
        T,
        np.asarray(inst["scale"]),
        np.asarray(inst["r_p"]),
        np.asarray(inst["r_c"]),
        angle,
        direction,
        np.asarray(inst["entry"]),
    )
    violations = count_violations(modules, crown, o, *args[:6], *args[6:], tol=tol)
    stats = ModularTreeStats(
        len(module), len(np.unique(module)), float(1 - alive.mean()), iterations, violations
    )
    return ModularTree(
        module,
        T,
        np.asarray(inst["parent"], dtype=np.int32),
        np.asarray(inst["depth"], dtype=np.int32),
        args[2],
        args[3],
        args[4],
        t_p,
        direction,
        args[7],
        attract,
        ~alive,
        stats,
    )
