"""Options of the decomposition stage, with VRTree's defaults (Appendix A, Table 2).

Lengths marked "at the 0.8 m scale" are in the normalised frame the paper works in: the tree scaled so
that its height is 0.8 m. The pipeline always computes in that frame and scales back at the end when
``height`` is None.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

SPECIES_COUNTS: dict[str, tuple[int, int]] = {
    "apple": (8, 53),
    "cherry": (10, 35),
    "eucalyptus": (8, 40),
    "ginkgo": (8, 36),
    "pine": (6, 40),
    "walnut": (10, 46),
}
"""VRTree Table 2: species -> (N_m, N_s = N_l), in the appendix's species order."""
REACH_WEIGHTS: dict[str, float] = {"pine": 0.0}
"""Species whose main branches are chosen by spread alone (``DecomposeOptions.reach_weight``): in an
excurrent crown (one leader, lateral whorls: the conifers) the main branches are the ones reaching
farthest from the leader. Every other species weighs reach and spread equally (0.5)."""
DEFAULT_COUNTS = (8, 40)
"""(N_m, N_l) for a species Table 2 does not list: the table's medians."""
WORK_HEIGHT = 0.8
"""Height (m) of the normalised frame every length at the 0.8 m scale refers to."""


@dataclass(frozen=True)
class DecomposeOptions:
    """Every parameter of ``pipeline.decompose``."""

    species: str = "unknown"
    """Species (lower case); picks N_m and N_l from Table 2 unless given below."""
    n_main: int | None = None
    """N_m: number of main branches (None: from ``species``)."""
    n_lobes: int | None = None
    """N_s = N_l: number of secondary branches and lobes (None: from ``species``)."""
    points: int = 12000
    """Downsample to this many points first (Appendix A: 12,000); 0 keeps all."""
    height: float | None = WORK_HEIGHT
    """Output height in metres (Appendix A: 0.8 m); None keeps the scan's own units and position."""
    k: int = 5
    """K: neighbours per point in the kNN graph (Appendix A)."""
    query_radius: float = 0.05
    """kNN query radius at the 0.8 m scale (Appendix A: 0.05); longer edges are dropped, then bridged."""
    alpha: float = 13.0
    """alpha of the alpha shape, as an inverse probe radius at the 0.8 m scale (Appendix A: 13)."""
    fps_candidates: int = 96
    """Farthest-point samples whose shortest paths are the main-branch candidates."""
    merge_threshold: float = 0.02
    """Algorithm 1: corresponding points closer than this (0.8 m scale) are merged."""
    resample: int = 24
    """Vertices each branch is resampled to for the shape-context similarity."""
    sc_bins: tuple[int, int, int] = (5, 6, 4)
    """Shape-context histogram bins: (log-radius, azimuth, elevation)."""
    step: float = 0.01
    """Vertex spacing of output branches at the 0.8 m scale."""
    reach_weight: float | None = None
    """Main-branch selection scores candidates by reach ** w * spread ** (1 - w) (``merge.select_mains``);
    None: 0 for the species in ``REACH_WEIGHTS`` (pine), 0.5 otherwise."""
    edge_power: float = 1.0
    """Main-branch routing uses edge length ** edge_power (1: the paper's Euclidean weights)."""
    leaf_edge_cost: float = 3.0
    """Edge-weight factor for edges that touch leaf points when routing the main branches (wood preferred)."""
    ground_band: float = 0.015
    """Ground, as a fraction of the scan height (0.3 m of 20 m): points within half of it of the ground
    plane sample the ground, and at least this much above the plane is cut (``preprocess.find_ground``)."""
    use_labels: bool = True
    """Use leaf/wood labels given with the input instead of the separation heuristic."""
    leaf_dimension: float = 2.1
    """Leaf/wood separation: points whose smoothed local dimension exceeds this are foliage."""
    leaf_off_fraction: float = 0.1
    """Below this fraction of leaf points the tree is leaf-off: lobes cluster the crown's wood."""
    min_points: int = 200
    """Fewer input points than this is an InputError."""
    pipe_exponent: float = 2.0
    """Pipe-model exponent: r_parent^e = sum r_child^e (2 = da Vinci)."""
    seed: int = 0
    """Seed of the numpy Generator for downsampling, FPS start and k-means."""

    def counts(self) -> tuple[int, int]:
        """(N_m, N_l) after applying species defaults."""
        n_m, n_l = SPECIES_COUNTS.get(self.species.lower(), DEFAULT_COUNTS)
        return (self.n_main or n_m, self.n_lobes or n_l)

    def selection_weight(self) -> float:
        """The reach weight w of main-branch selection after applying species defaults."""
        if self.reach_weight is not None:
            return float(self.reach_weight)
        return REACH_WEIGHTS.get(self.species.lower(), 0.5)

    @property
    def alpha_radius(self) -> float:
        """Alpha-shape probe radius at the 0.8 m scale (1 / alpha)."""
        return 1.0 / self.alpha

    def as_dict(self) -> dict[str, Any]:
        """JSON-able dict of every field, with the resolved N_m and N_l."""
        d = dataclasses.asdict(self)
        d["sc_bins"] = list(self.sc_bins)
        d["n_main"], d["n_lobes"] = self.counts()
        d["reach_weight"] = self.selection_weight()
        return d
