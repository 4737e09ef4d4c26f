"""The result of modular growth: placed module instances plus statistics."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ModularTreeStats:
    modules_placed: int
    """Instances placed, trunk included."""
    types_used: int
    """Distinct module types among the instances."""
    reached_fraction: float
    """Fraction of attraction points pruned by the kill distance (reached by a branch)."""
    iterations: int
    """Layers grown (global + local steps run)."""
    violations: dict[str, int] = field(default_factory=dict)
    """Constraint violations counted on the result: 'scale', 'radius', 'angle', 'crown'."""


@dataclass(frozen=True)
class ModularTree:
    module: np.ndarray
    """(K,) int32 index into the ModuleSet of each instance; instance 0 is the trunk."""
    T_world_module: np.ndarray
    """(K, 4, 4) float64 world (Z up, metres) from module frame: rotation, uniform scale, translation."""
    parent: np.ndarray
    """(K,) int32 parent instance, -1 for the trunk."""
    depth: np.ndarray
    """(K,) int32 layer (0 = trunk, 1 = first layer of branches, ...)."""
    scale: np.ndarray
    """(K,) float64 uniform scale s of each instance."""
    parent_radius: np.ndarray
    """(K,) float64 r_p, parent skeleton radius at the branching point (world; NaN for the trunk)."""
    child_radius: np.ndarray
    """(K,) float64 r_c s, the instance's base radius in world units."""
    parent_tangent: np.ndarray
    """(K, 3) float64 unit parent skeleton tangent t_p at the branching point (NaN for the trunk)."""
    direction: np.ndarray
    """(K, 3) float64 unit branching direction v_c (the module's +Z in world)."""
    entry: np.ndarray
    """(K,) float64 distance along ``direction`` before the branch enters the crown (0: starts inside)."""
    attraction_points: np.ndarray
    """(N, 3) float64 the attraction points used."""
    reached: np.ndarray
    """(N,) bool attraction points pruned by the kill distance."""
    stats: ModularTreeStats
    """Counts and the constraint check."""

    @property
    def branch_angle(self) -> np.ndarray:
        """(K,) float64 angle between t_p and v_c in radians (NaN for the trunk)."""
        return np.arccos(np.clip((self.parent_tangent * self.direction).sum(axis=1), -1.0, 1.0))
