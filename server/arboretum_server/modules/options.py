"""Options of the modular-tree growth, with the defaults and symbols of Takikawa et al. (GI 2025).

Lengths given as fractions are relative to the largest axis of the bounding box of trunk and crown, as in
the paper (its scene units do not transfer; see docs/modules.md). ``fit.py`` scales the module set and the
trunk to the crown, so that box, and every distance, follows the crown's size.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ModularTreeOptions:
    n_interior: int = 5000
    """Attraction points sampled inside the crown (Sec. 4.2: 5,000)."""
    n_surface: int = 2000
    """Attraction points sampled on the crown surface (Sec. 4.2: 2,000)."""
    scale_lower: float = 0.5
    """s_l, lowest uniform module scale (Sec. 3: 0.5)."""
    scale_upper: float = 2.0
    """s_u, highest uniform module scale (Sec. 3: 2.0)."""
    angle_lower_deg: float = 15.0
    """theta_l, lowest angle between parent tangent and child direction, degrees (Sec. 3: 15)."""
    angle_upper_deg: float = 90.0
    """theta_u, highest branching angle, degrees (Sec. 3: 90)."""
    direction_bias: float = 1.0
    """Blend of the direction adjustment (Sec. 4.4.2, cut off in the paper): 0 = off, 1 = the angle is
    clamped into [theta_l, theta_u]; in between, the angle moves that fraction of the way."""
    spacing_fraction: float = 0.1
    """Delta x, spacing of branching-point stations along a module's skeleton, as a fraction of the
    module's size (Fig. 6)."""
    junctions: int = 3
    """n, number of rays (junction points) cast around the skeleton at each station (Fig. 6)."""
    junction_angle_deg: float = 137.5
    """alpha, rotation of the ray fan about the tangent from one station to the next, degrees (Fig. 6)."""
    base_clearance: float = 0.15
    """No stations on the first part of a module (fraction of its size): keeps children off the joint."""
    cull_fraction: float = 0.3
    """Fraction of branching points removed at random (Sec. 4.3: "culled with a random variable")."""
    neighbours: int = 25
    """Branching points paired with each attraction point (Sec. 4.3: the 25 closest)."""
    saturation_fraction: float = 0.2
    """C of Eq. 2 as a fraction of the largest bounding-box axis (Sec. 4.3.2: about 1/5)."""
    kill_fraction: float = 0.08
    """d_k as a fraction of the largest bounding-box axis (Sec. 4.4.3: 1/20 to 1/10)."""
    surface_weight: float = 0.5
    """Weight of the distance to the crown surface in the final target distance, first layer (Sec. 4.4.3)."""
    surface_weight_decay: float = 0.5
    """Factor applied to ``surface_weight`` each layer ("in early iterations")."""
    prune_trunk_outside: bool | None = None
    """Prune trunk branching points outside the crown. None (auto): prune unless no trunk point lies
    inside, the "trunk outside the crown" case of Sec. 4.3 / Fig. 11. Branch modules' points outside
    the crown are always pruned."""
    crown_tolerance_fraction: float = 0.002
    """How far (fraction of the largest axis) a placed module's skeleton, or a sphere-traced path, may poke
    out of the crown (numerical slack of the trilinear SDF)."""
    max_iterations: int = 30
    """Stop after this many layers even if attraction points remain."""
    sdf_resolution: int = 64
    """Cells along the largest axis of the crown's signed-distance grid."""
