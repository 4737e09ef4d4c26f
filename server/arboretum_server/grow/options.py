"""Options of procedural growth (VRTree section 3.5) with the paper's defaults."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from arboretum_library.errors import InputError

GRAVITY = (0.0, 0.0, -1.0)
"""V_g in our Z-up world frame (the paper's (0, -1, 0) is Unity's Y-up frame)."""


@dataclass(frozen=True)
class GrowOptions:
    """Space colonization in lobes, radii and leaves. Lengths in metres unless said otherwise."""

    alpha: float = 1.6
    """α, weight of gravity V_g in Eq. 2 (VRTree, after Guo et al. 2018)."""
    beta: float = 0.3
    """β, weight of the attraction vector V_att in Eq. 2."""
    step: float | None = None
    """D, the growth radius: distance between a node and its child. None: 1/6 of the median lobe
    equivalent-sphere radius (so every lobe is about a dozen steps across)."""
    influence: float | None = 5.0
    """d_i, influence distance in units of ``step``: an attraction point pulls its nearest node only
    when closer than this. None: unlimited (every live point pulls its nearest node; slower)."""
    kill: float = 2.0
    """d_k, kill distance in units of ``step``: an attraction point dies when a node comes this close."""
    attraction_density: float = 0.15
    """Interior attraction points per step³ of lobe volume, sampled inside the closed hull, added to the
    hull vertices (the paper's attraction points)."""
    density: float = 1.0
    """Global twig density: multiplies the number of interior attraction points of every lobe."""
    lobe_density: Mapping[int, float] = field(default_factory=dict)
    """Per-lobe twig density multipliers by lobe index (missing lobes: 1.0)."""
    max_points_per_lobe: int = 20000
    """Cap on attraction points in one lobe (keeps a huge lobe from stalling growth)."""
    max_iterations: int = 200
    """Upper bound on colonization iterations."""
    min_spacing: float = 0.5
    """A proposed node closer than this many steps to an existing node is refused and its parent stops."""
    pipe_exponent: float = 2.0
    """Pipe-model exponent e in r_parent^e = sum r_child^e (da Vinci's rule 2.0; Leonardo 2.0-2.5)."""
    tip_radius: float | None = None
    """Radius of a twig tip in metres before its lobe is fitted to its branch (see ``branch_radii``).
    None: 0.08 × step (ours, paper-free)."""
    min_twig_radius: float = 0.3
    """Fitting a lobe's twigs to its branch never thins a twig below this fraction of ``tip_radius``
    (nor above the branch radius at the bud)."""
    branch_radii: str = "auto"
    """"hbl": main and secondary branches keep the HBL's radii and each lobe's twigs are scaled to fit
    under the branch they grow from; "pipe": the pipe model over the whole tree (twig tips up to the
    root); "auto": "hbl" when the HBL's radii are consistent (no child thicker than its parent at a
    joint, not all equal), else "pipe"."""
    leaf_density: float = 1.0
    """Expected leaf cards per twig node near the tips (Poisson)."""
    leaf_size: float | None = None
    """Leaf card length in metres. None: 1.2 × step. Sets the cards' size only, never their number:
    which cards are kept is decided at the default size (``leaves.place_leaves``)."""
    leaf_tip_depth: int = 3
    """Leaves grow on twig nodes at most this many nodes away from a tip."""
    leaf_jitter: float = 0.35
    """Standard deviation (radians, roughly) of the random tilt of a leaf's facing direction."""

    def __post_init__(self) -> None:
        positive = {
            "kill": self.kill, "attraction_density": self.attraction_density, "density": self.density,
            "pipe_exponent": self.pipe_exponent, "max_iterations": self.max_iterations,
            "max_points_per_lobe": self.max_points_per_lobe,
        }
        for name in ("step", "influence", "tip_radius", "leaf_size"):
            if getattr(self, name) is not None:
                positive[name] = getattr(self, name)
        for name, value in positive.items():
            if not value > 0:
                raise InputError(f"grow option {name}: must be > 0, got {value}")
        if self.branch_radii not in ("auto", "hbl", "pipe"):
            raise InputError(f"grow option branch_radii: must be auto, hbl or pipe, got {self.branch_radii!r}")
        for name in ("alpha", "beta", "leaf_density", "leaf_jitter", "min_spacing", "leaf_tip_depth",
                     "min_twig_radius"):
            if getattr(self, name) < 0:
                raise InputError(f"grow option {name}: must be >= 0, got {getattr(self, name)}")
        if any(v < 0 for v in self.lobe_density.values()):
            raise InputError("grow option lobe_density: multipliers must be >= 0")

    def lobe_multiplier(self, lobe: int) -> float:
        """Twig density of lobe ``lobe``: the global density times its own multiplier."""
        return self.density * float(self.lobe_density.get(lobe, 1.0))
