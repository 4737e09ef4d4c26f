"""Fit a module set and its trunk to a crown of any size, then grow (shared by the CLI and the server job).

The paper's lengths are in scene units (Takikawa et al. 2025 give no crown or module dimensions); what
matters is the size of the modules *relative to the crown*. So the module set is scaled as a whole by
``k = crown's largest axis / (crown_lengths x median branch-module size)`` before growing: the same crown
shape at 0.2 m or 200 m gets the same tree, scaled. The trunk stands at ``root``, upright, scaled so its
top reaches ``trunk_fraction`` of the way up the crown, and never longer than the crown allows
(``max_trunk_fraction``); a crown mesh high above z = 0 (a georeferenced crown) gets its trunk's base a
quarter of the crown's height below its bottom (``crown_root``), not on z = 0. Growth distances (C, d_k,
tolerance) are fractions of the trunk-and-crown box (``grow.py``, the paper's definition), which therefore
scales with the crown and does not grow with the crown's height above z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.geometry import make_transform

from .moduleset import Module, ModuleSet

LOW_REACH = 0.5
"""A crown-grown tree that reaches less than this fraction of its attraction points gets a note."""


@dataclass(frozen=True)
class FitOptions:
    crown_lengths: float = 8.0
    """The crown's largest axis in median branch-module lengths after scaling the set (ours; the
    default set's median branch module is about 1 m, so an 8 m crown keeps the set at scale 1)."""
    trunk_fraction: float = 1.0 / 3.0
    """Height of the trunk's top above the crown's bottom, as a fraction of the crown's height."""
    min_trunk_fraction: float = 0.1
    """Shortest trunk, as a fraction of the crown's height (a root at or above the trunk's target)."""
    max_trunk_fraction: float = 5.0
    """Longest trunk, as a fraction of the crown's height (ours; a crown ratio of about 0.2, the lowest of
    forest-grown trees): a root farther below the crown gets a trunk that stops short of it, not one that
    dwarfs it (d_k, a fraction of the trunk-and-crown box, would cover the crown from the trunk alone)."""
    clear_bole_fraction: float = 0.25
    """A crown mesh's stem below the crown, as a fraction of the crown's height (ours; crown ratio 0.8, an
    open-grown tree): its trunk stands this far below the crown's bottom, or on z = 0 (the ground) when the
    crown's bottom is lower than that."""


def module_scale(modules: ModuleSet, crown_axis: float, options: FitOptions = FitOptions()) -> float:
    """k (> 0): the factor that makes ``crown_axis`` (metres) ``crown_lengths`` median branch modules."""
    sizes = [m.size for m in modules.modules if not m.is_trunk]
    if not sizes or crown_axis <= 0:
        raise InputError("crown: has no extent (all its vertices coincide)")
    return float(crown_axis) / (options.crown_lengths * float(np.median(sizes)))


def scale_module(module: Module, k: float) -> Module:
    """``module`` with its mesh and skeleton (points, radii, base) scaled by ``k`` about its base."""
    sk = module.skeleton
    sk = replace(sk, points=sk.points * k, radius=sk.radius * k, base=sk.base * k)
    return replace(module, vertices=module.vertices * k, skeleton=sk)


def scale_module_set(modules: ModuleSet, k: float) -> ModuleSet:
    """Every module scaled by ``k`` (uniform, about its base at the origin)."""
    return ModuleSet(tuple(scale_module(m, k) for m in modules.modules))


def trunk_transform(modules: ModuleSet, crown, root, options: FitOptions = FitOptions()) -> np.ndarray:
    """(4, 4) trunk placement: base at ``root`` (3,), upright, scaled so its top is ``trunk_fraction`` of the
    way up the crown (at least ``min_trunk_fraction``, at most ``max_trunk_fraction`` of the crown's height
    above ``root``)."""
    trunks = modules.trunk_indices
    trunk = modules.modules[int(trunks[0] if len(trunks) else modules.branch_indices[0])]
    lo, hi = crown.bounds[0, 2], crown.bounds[1, 2]
    height = min(max(lo + (hi - lo) * options.trunk_fraction - float(root[2]),
                     (hi - lo) * options.min_trunk_fraction),
                 (hi - lo) * options.max_trunk_fraction)
    top = float(trunk.vertices[:, 2].max())
    if top <= 0:
        raise InputError(f"module {trunk.name}: its top is not above its base")
    return make_transform(None, np.asarray(root, dtype=np.float64), height / top)


def crown_root(vertices: np.ndarray, options: FitOptions = FitOptions()) -> np.ndarray:
    """(3,) trunk position under a crown mesh's ``vertices`` (V, 3): the centre of its footprint,
    ``clear_bole_fraction`` of the crown's height below its bottom, or on z = 0 when that is lower (at the
    crown's bottom when the crown reaches below z = 0)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    z = max(min(float(lo[2]), 0.0), float(lo[2] - options.clear_bole_fraction * (hi[2] - lo[2])))
    return np.r_[(lo[:2] + hi[:2]) / 2, z]


def grow_in_crown(modules: ModuleSet, meshes: list, root, options, rng: np.random.Generator,
                  fit: FitOptions = FitOptions()):
    """Crown of ``meshes`` [(V, 3), (F, 3)], ``modules`` scaled to it, trunk at ``root`` (3,), grown.

    Returns (ModularTree, the scaled ModuleSet the tree's module indices refer to, k).
    """
    from .crown import crown_from_meshes
    from .grow import grow_modular_tree

    crown = crown_from_meshes(meshes, options.sdf_resolution)
    k = module_scale(modules, float(np.ptp(crown.bounds, axis=0).max()), fit)
    scaled = scale_module_set(modules, k)
    T0 = trunk_transform(scaled, crown, root, fit)
    return grow_modular_tree(scaled, crown, options, rng, T_world_trunk=T0), scaled, k


def default_module_set() -> ModuleSet:
    """The default module set, ``assets/modules/default`` (the same for the CLI and the server)."""
    from arboretum_library.assets import asset_path

    from .moduleset import load_module_set

    return load_module_set(asset_path("modules", "default"))


def hbl_crown(hbl, what: str) -> tuple[list, np.ndarray]:
    """The lobe hulls [(V, 3), (F, 3)] of ``hbl`` (the crown) and its first main branch's base (3,), the
    trunk's position; errors name ``hbl`` as ``what``."""
    if not hbl.lobes:
        raise InputError(f"{what}: has no lobes (no crown to grow in)")
    if not hbl.branches:
        raise InputError(f"{what}: has no branches (no main branch base for the trunk)")
    meshes = [(lb.hull_vertices, lb.hull_faces) for lb in hbl.lobes]
    return meshes, np.asarray(hbl.branches[0].points[0], dtype=np.float64)


def reach_note(reached_fraction: float, modules_placed: int | None = None) -> str | None:
    """A warning line when few attraction points were reached or only the trunk was placed
    (``modules_placed`` <= 1, when given), else None."""
    if modules_placed is not None and modules_placed <= 1:
        return (f"only the trunk was placed (no branch module fits the crown); it reaches "
                f"{100 * reached_fraction:.0f}% of the attraction points alone")
    if reached_fraction >= LOW_REACH:
        return None
    return (f"only {100 * reached_fraction:.0f}% of the attraction points were reached: the crown is "
            "filled sparsely (small or thin crown parts the modules do not fit into)")
