"""Options of the decomposition stage, with VRTree's defaults (Appendix A, Table 2).

Lengths marked "at the 0.8 m scale" are in the normalised frame the paper works in: the tree scaled so
that its height is 0.8 m. The pipeline always computes in that frame and scales back at the end when
``height`` is None.

Every value is checked when the options are made (``WHOLE_LIMITS``, ``REAL_LIMITS``): a Python caller,
the service (``refine.open``, ``library.import``) and the command line all get one ``InputError`` naming
the option, e.g. ``decomposition option k: must be a whole number >= 2 and <= 100, got 0``. Limits that
depend on the cloud (lobes per point, main branches per candidate path) are checked while decomposing.
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.pointio import MAX_COORDINATE

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

WHOLE_LIMITS: dict[str, tuple[int, int | None]] = {
    "n_main": (1, None), "n_lobes": (1, None),  # at most the candidate paths, a tenth of the points: per cloud
    "points": (0, None), "seed": (0, None),  # 0: all points; numpy seeds are whole numbers >= 0
    "min_points": (10, None),  # preprocess.POINTS_PER_LOBE: fewer cannot hold one lobe
    "k": (2, 100),  # k = 1 pairs points up: scan 07 falls into 3,566 components, 76 s instead of 0.5 s
    "fps_candidates": (1, 1000),  # one shortest path each: 1.3 s at 1,000 and 4.5 s at 5,000 on scan 07
    "resample": (2, 100),  # shape contexts need 2 vertices; B x n^2 vectors: 2.2 s at 100, 25 s at 400
}
"""Whole-number options: name -> (lowest, highest or None for no limit). bool is no number; 2.0 is no
int (the service turns a whole float into an int before it makes the options)."""
REAL_LIMITS: dict[str, tuple[float, float, bool]] = {
    "height": (0.0, MAX_COORDINATE, True),  # metres; the largest coordinate a scan may hold
    "query_radius": (0.001, WORK_HEIGHT, False),  # below 1 mm nearly all edges are bridges (5.8 s); above
    # the tree's height nothing is dropped any more
    "alpha": (1.0, 1000.0, False),  # probe radius 1/alpha from 1 m (the whole tree) down to 1 mm (scan 07:
    # 39 of 40 lobes fall back to convex hulls at alpha 500)
    "merge_threshold": (0.0, 0.08, False),  # a tenth of the tree: scan 07 keeps 8 main branches up to 0.03,
    # 6 at 0.05, 3 at 0.07 and 1 at 0.1
    "step": (0.001, 0.1, False),  # time grows as 1/step (2.1 s at 1 mm, 7.1 s at 0.3 mm on scan 07); a
    # main branch needs 2 steps of new wood: scan 07 loses one at 0.2
    "reach_weight": (0.0, 1.0, False),  # the exponent w of reach ** w * spread ** (1 - w)
    "edge_power": (0.0, 10.0, True),  # scipy refuses power 0; a negative one makes long edges cheap;
    # lengths (>= 1e-12) ** 26 underflow
    "leaf_edge_cost": (0.0, 1e6, True),  # a factor on edge weights: 0 makes leaf edges free
    "ground_band": (0.0, 0.1, True),  # a fraction of the height; the ground search reaches 10 bands up
    "leaf_dimension": (0.0, 3.0, False),  # a local dimension lies in 0..3: beyond, all or no points are leaf
    "leaf_off_fraction": (0.0, 1.0, False),  # a fraction of the points
    "pipe_exponent": (1.0, 4.0, False),  # da Vinci 2, Murray 3; synth species allow the same 1..4
}
"""Real options: name -> (low, high, low excluded). Integers pass; bool, NaN and infinities do not."""
OPTIONAL: dict[str, str] = {
    "n_main": "the species' count", "n_lobes": "the species' count", "height": "keep the scan's units",
    "reach_weight": "the species' weight",
}
"""Options that may be None, and what None means."""
MAX_BINS = 16
"""Most shape-context bins along one axis (``sc_bins``): 16 x 16 x 16 takes 2 s on scan 07, 32 cubed 23 s."""


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
    plane sample the ground, and at least this much above the plane is cut (``ground.find_ground``)."""
    use_labels: bool = True
    """Use leaf/wood labels given with the input instead of the separation heuristic."""
    leaf_off: bool = False
    """The tree bore no leaves when scanned (the user says so: a winter scan): every point is reported
    wood (``HBL.labels``, the leaf count). No test of the cloud itself tells leaf-off from leaf-on well
    enough (session 13: about 45 statistics measured), so it is declared. The guessed split still steers
    routing and lobes as without the flag ("leaf" in a bare crown is fine, space-filling wood, which the
    main branches are kept out of), so the geometry is the same; ``stats['fine_wood_points']`` counts it."""
    leaf_dimension: float = 2.1
    """Leaf/wood separation: points whose smoothed local dimension exceeds this are foliage."""
    leaf_off_fraction: float = 0.1
    """Below this fraction of leaf points the tree is leaf-off: lobes cluster the crown's wood."""
    min_points: int = 200
    """Fewer input points than this is an InputError."""
    pipe_exponent: float = 2.0
    """Pipe-model exponent: r_parent^e = sum r_child^e (2 = da Vinci)."""
    seed: int = 0
    """Seed of the numpy Generator for downsampling and k-means (farthest-point sampling starts at the root and
    draws nothing; the ground search and the base-band subsample use their own fixed seed)."""

    def __post_init__(self) -> None:
        check_options(self)

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


def check_options(o: DecomposeOptions) -> None:
    """``InputError`` naming the first option of ``o`` whose value is of the wrong type or out of its
    limits (``WHOLE_LIMITS``, ``REAL_LIMITS``, ``OPTIONAL``)."""
    if not isinstance(o.species, str):
        _refuse("species", "must be text", o.species)
    for name in ("use_labels", "leaf_off"):
        if not isinstance(getattr(o, name), bool | np.bool_):
            _refuse(name, "must be true or false", getattr(o, name))
    for name, (lo, hi) in WHOLE_LIMITS.items():
        value = getattr(o, name)
        if value is None and name in OPTIONAL:
            continue
        if not (_whole(value) and value >= lo and (hi is None or value <= hi)):
            _refuse(name, f"must be a whole number >= {lo}" + ("" if hi is None else f" and <= {hi}"), value)
    for name, (lo, hi, lo_open) in REAL_LIMITS.items():
        value = getattr(o, name)
        if value is None and name in OPTIONAL:
            continue
        if not (_real(value) and (value > lo if lo_open else value >= lo) and value <= hi):  # NaN fails
            _refuse(name, f"must be a number {'>' if lo_open else '>='} {lo:g} and <= {hi:g}", value)
    bins = o.sc_bins
    if not (isinstance(bins, tuple | list) and len(bins) == 3 and all(_whole(b) and 1 <= b <= MAX_BINS for b in bins)):
        _refuse("sc_bins", f"must be 3 whole numbers from 1 to {MAX_BINS} (log-radius, azimuth, elevation bins)", bins)


def _whole(value: Any) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _refuse(name: str, rule: str, value: Any) -> None:
    if name in OPTIONAL:
        rule += f", or None ({OPTIONAL[name]})"
    if name == "points":
        rule += " (0: all)"
    shown = repr(value) if isinstance(value, str | bytes) else str(list(value) if isinstance(value, tuple) else value)
    hint = " (a float; give an int)" if isinstance(value, float) and value.is_integer() and name in WHOLE_LIMITS else ""
    shown = shown if len(shown) <= 80 else shown[:77] + "..."
    raise InputError(f"decomposition option {name}: {rule}, got {shown}{hint}")
