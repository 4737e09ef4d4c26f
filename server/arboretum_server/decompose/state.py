"""The state a decomposition keeps so refinement operations redo only what they must."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix

from arboretum_library.model import HBL, Branch, Level, Lobe

from .merge import BranchSet
from .options import WORK_HEIGHT, DecomposeOptions
from .radii import MAIN_TIP, lobe_weights, pipe_radii


@dataclass(frozen=True, eq=False)
class LobeState:
    """One lobe and its secondary branch, in the 0.8 m working frame."""

    members: np.ndarray
    """(M,) int64: indices of the lobe's points in ``Decomposition.points``."""
    centre: np.ndarray
    """(3,) float64: k-means centre."""
    hull_vertices: np.ndarray
    """(V, 3) float64: closed hull vertices."""
    hull_faces: np.ndarray
    """(F, 3) int32: outward triangles."""
    alpha: bool
    """True for an alpha shape, False for the convex-hull fallback."""
    segment: np.ndarray
    """(S, 3) float64: the secondary branch, from its connection point on a main branch to the tip."""
    parent: int
    """Index of the main branch it connects to."""
    parent_vertex: int
    """Vertex of that main branch where it connects."""
    steps: tuple[float, ...] | None = None
    """The ``lobes.RADIUS_STEPS`` up to the one its plain hull used (``lobes.plain_steps``), when known:
    carving within them never grows the hull. None: computed again when needed."""


@dataclass(frozen=True, eq=False)
class Decomposition:
    """A decomposed tree: the HBL plus the cached arrays the refinement operations reuse."""

    hbl: HBL
    """The whole-tree HBL in the output frame (0.8 m tall with the root at the origin by default)."""
    points: np.ndarray
    """(N, 3) float64: the downsampled points in the 0.8 m working frame."""
    labels: np.ndarray
    """(N,) uint8: WOOD/LEAF per point as reported (all WOOD when ``options.leaf_off``)."""
    root_index: int
    """Index of the root point."""
    pred: np.ndarray
    """(N,) int32: predecessor of each point on the zone-penalised shortest-path tree (-1 at the root)."""
    mains: BranchSet
    """Main branches (working frame) with their full root paths."""
    lobes: tuple[LobeState, ...]
    lobe_of: np.ndarray
    """(N,) int32: lobe of each point, -1 for none."""
    trunk_radius: float
    """Trunk radius at the base, working frame."""
    options: DecomposeOptions
    scale: float
    """Working units per scan unit."""
    root_scan: np.ndarray
    """(3,) float64: the root in the scan frame."""
    source_index: np.ndarray
    """(N,) int64: index of each point in the input array (of its first row when it was repeated)."""
    adjacency: csr_matrix | None = None
    """(N, N) the bridged kNN graph; weights are edge lengths, a mutual neighbour pair counted twice
    (``graph.knn_graph``)."""
    timing: dict[str, float] = field(default_factory=dict)
    """Seconds per step."""
    stats: dict[str, Any] = field(default_factory=dict)
    """Counts: components, bridges, leaf points, alpha shapes, fallbacks, ..."""
    tau: float = 0.02
    """The merge threshold used (0.8 m frame): the option, raised to the trunk radius for thick trunks."""
    grid: Any = None
    """The BoxGrid that centres branch vertices in the cloud."""
    zone_sources: np.ndarray | None = None
    """(N,) int64: ``secondary.zone_sources`` of the lobes' points (the points with ``lobe_of`` >= 0); None:
    computed again when needed."""

    def to_output(self, p: np.ndarray) -> np.ndarray:
        """Working-frame points (..., 3) in the output frame."""
        if self.options.height is None:
            return p / self.scale + self.root_scan
        return p * (self.options.height / WORK_HEIGHT)

    @property
    def output_scale(self) -> float:
        """Output units per working unit."""
        return 1.0 / self.scale if self.options.height is None else self.options.height / WORK_HEIGHT


def build_hbl(d: Decomposition) -> HBL:
    """The HBL of ``d``'s mains and lobes in the output frame (radii by the pipe model)."""
    m = d.mains
    n_main = len(m.segments)
    segs = list(m.segments) + [lb.segment for lb in d.lobes]
    parents = list(m.parents) + [lb.parent for lb in d.lobes]
    pvs = list(m.parent_vertex) + [lb.parent_vertex for lb in d.lobes]
    tips = [MAIN_TIP] * n_main + list(lobe_weights(np.array([len(lb.members) for lb in d.lobes])))
    radii = pipe_radii([len(s) for s in segs], parents, pvs, tips, d.trunk_radius, d.options.pipe_exponent)
    k = d.output_scale
    branches = [
        Branch(d.to_output(s), r * k, p, pv, Level.MAIN if i < n_main else Level.SECONDARY)
        for i, (s, r, p, pv) in enumerate(zip(segs, radii, parents, pvs))
    ]
    lobes = [
        Lobe(d.to_output(d.points[lb.members]), d.to_output(lb.hull_vertices), lb.hull_faces,
             d.to_output(lb.centre), n_main + j)
        for j, lb in enumerate(d.lobes)
    ]
    return HBL(d.to_output(np.zeros(3)), branches, lobes, d.to_output(d.points), d.labels)
