"""Count violations of the paper's constraints (Sec. 3) on a grown modular tree."""

from __future__ import annotations

import numpy as np

from .crown import Crown, crown_sdf
from .moduleset import ModuleSet
from .options import ModularTreeOptions


def skeleton_world(modules: ModuleSet, module: int, T: np.ndarray) -> np.ndarray:
    """(P, 3) skeleton points of ``module`` placed by ``T`` (4, 4)."""
    return modules.modules[module].skeleton.points @ T[:3, :3].T + T[:3, 3]


def crown_excess(modules: ModuleSet, crown: Crown, module, T, direction, entry) -> np.ndarray:
    """(K,) largest SDF over each instance's skeleton points past its crown entry (trunk: -inf)."""
    out = np.full(len(module), -np.inf)
    if len(module) < 2:
        return out
    pts = [skeleton_world(modules, int(module[i]), T[i]) for i in range(1, len(module))]
    owner = np.concatenate([np.full(len(p), i + 1) for i, p in enumerate(pts)])
    pts = np.concatenate(pts)
    along = ((pts - T[owner, :3, 3]) * direction[owner]).sum(axis=1)
    d = np.where(along >= entry[owner], crown_sdf(crown, pts), -np.inf)
    np.maximum.at(out, owner, d)
    return out


def count_violations(
    modules: ModuleSet,
    crown: Crown,
    options: ModularTreeOptions,
    module,
    T,
    scale,
    parent_radius,
    child_radius,
    branch_angle,
    direction,
    entry,
    tol: float,
) -> dict[str, int]:
    """Violations per constraint over the branch instances (index 1 on; the trunk is given)."""
    b = slice(1, None)
    eps = 1e-9
    scale_bad = (scale[b] < options.scale_lower - eps) | (scale[b] > options.scale_upper + eps)
    radius_bad = child_radius[b] > parent_radius[b] * (1 + eps)
    lo, hi = np.radians(options.angle_lower_deg), np.radians(options.angle_upper_deg)
    angle_bad = (branch_angle[b] < lo - 1e-6) | (branch_angle[b] > hi + 1e-6)
    crown_bad = crown_excess(modules, crown, module, T, direction, entry)[b] > tol
    return {
        "scale": int(scale_bad.sum()),
        "radius": int(radius_bad.sum()),
        "angle": int(angle_bad.sum()) if options.direction_bias >= 1.0 else 0,
        "crown": int(crown_bad.sum()),
    }
