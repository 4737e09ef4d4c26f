"""``decompose``: a point cloud to a whole-tree HBL (VRTree section 3.4, Fig. 4, Appendix A).

Steps (each timed in ``Decomposition.timing``): prepare (repeated points merged, ground cut, downsample,
strays left out, root and trunk columns, scale) -> graph (kNN K=5 within r=0.05, bridged) -> separate
(leaf/wood, on the graph's neighbours) -> mains (Dijkstra from the root, FPS endpoints, shortest paths,
hooked ones rerouted across scan gaps, selection, Algorithm 1 step 1, smoothing) -> lobes (bare trunk
to wood, foliage points, k-means into N_l clusters) -> secondary (alpha shapes, shortest paths to the
lobe centres, Algorithm 1 step 2, Eq. 1, smoothing, repairs of branches entering foreign lobes:
rerouting, straight and bent, carving, ``tunnel.behind``) -> hbl (pipe-model radii, records).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from arboretum_library.model import LEAF, WOOD
from arboretum_library.progress import ProgressFn, no_progress

from .graph import Graph, gap_graph, knn_graph, query, shortest_paths, weighted
from .grid import BoxGrid
from .lobes import kmeans
from .merge import drop, merge_mains, select_mains
from .options import WORK_HEIGHT, DecomposeOptions
from .preprocess import prepare
from .radii import path_radii, trunk_radius
from .sampling import farthest_points
from .secondary import branch_paths, make_lobes, zone_sources, zones
from .separate import separate
from .smooth import smooth_branchset
from .state import Decomposition, build_hbl

STEPS = ("prepare", "graph", "separate", "mains", "lobes", "secondary", "hbl")
CENTRE_RADIUS = 0.02
"""Radius (0.8 m frame) of the centroid that centres branch vertices in the cloud."""
CROWN_BASE = 0.04
"""Points below this height (0.8 m frame, 5 % of the tree) never join a crown's foliage (buttresses,
ground). Not the crown base of ``bare_trunk`` and the docs (the lowest main-branch fork)."""
BARE_TRUNK_RADII = 2.5
"""Guessed leaf points below the crown base within this many local trunk radii of the trunk are wood."""
CLEARANCE_PIPE = 2.0
"""A point is on a main branch's wood only within this many times its vertex's pipe-model radius
(``main_clearance``)."""
HOOK_DROP = 0.05
"""A main-branch candidate falling more than this fraction of the height below a point it reached
before is routed again across scan gaps (``main_branches``); drooping tips of the synthetic trees fall
up to 0.15, but there the rerouted path falls as far and is not taken."""


class _Clock:
    def __init__(self, progress: ProgressFn) -> None:
        self.timing: dict[str, float] = {}
        self.progress = progress
        self.t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.timing[name] = now - self.t
        self.t = now
        self.progress(STEPS.index(name) + 1, len(STEPS), f"decompose: {name}")


def width_ratio(pts: np.ndarray) -> float:
    """The spread (standard deviation) of ``pts`` (N, 3) across their principal axis over the spread
    along it: 0.005-0.007 for a noisy straight line, 0.08 for the slender real pine (scan 10), 0.12 or
    more for the other trees measured (session 7)."""
    ev = np.linalg.eigvalsh(np.cov(pts.T))
    return float(np.sqrt(max(ev[1], 0.0) / max(ev[2], 1e-300)))


def main_clearance(mains, pts: np.ndarray, tau: float, tree: cKDTree, r_trunk: float) -> np.ndarray:
    """(N,) bool: points off the main branches' wood.

    A point is on a main branch when it lies closer to its nearest main-branch vertex than that
    vertex's local radius, estimated as 1.3 x the median distance of its 8 nearest cloud points
    (clipped to [0.004, tau]): thin branches keep the leaves around them, thick trunks keep their bark.
    That radius is capped at ``CLEARANCE_PIPE`` times the pipe-model radius of the vertex (the trunk's
    ``r_trunk``, shared among the main-branch tips, ``radii.path_radii``): where a main branch ends among
    sparse leaves, their spacing is no measure of its wood (session 31: the harmonic walnut, seed 3, through
    the virtual scanner, left out 1.7 cm round its tips, 6 % of its leaf points).
    """
    verts = np.concatenate([mains.reference(b) for b in range(len(mains.full))])  # unsmoothed: on the wood
    spacing = np.minimum(1.3 * np.median(tree.query(verts, k=8)[0], axis=1), tau)
    r = np.maximum(np.minimum(spacing, CLEARANCE_PIPE * np.concatenate(path_radii(mains.owner, r_trunk))), 0.004)
    d, i = query(cKDTree(verts), pts)
    return d > r[i]


def bare_trunk(pts: np.ndarray, mains) -> np.ndarray:
    """(N,) bool: points on the bare trunk, below the crown base (the lowest main-branch fork).

    A point is on it when its nearest main-branch vertex is a trunk vertex below the crown base and it
    lies within ``BARE_TRUNK_RADII`` times that vertex's local radius (the mean distance of the points
    whose nearest vertex it is). The box-counting separation reads rough bark and buttresses as foliage.
    """
    trunk = mains.segments[0]
    forks = [pv for p, pv in zip(mains.parents, mains.parent_vertex) if p == 0]
    base = min(forks) if forks else len(trunk) - 1
    verts = np.concatenate(mains.segments)
    d, i = query(cKDTree(verts), pts)
    n = np.bincount(i, minlength=len(verts))
    r = np.bincount(i, weights=d, minlength=len(verts)) / np.maximum(n, 1)
    return (i < base) & (d <= BARE_TRUNK_RADII * r[i])


def foliage_points(labels: np.ndarray, pts: np.ndarray, off_main: np.ndarray, o: DecomposeOptions,
                   bare: np.ndarray) -> tuple[np.ndarray, str]:
    """Indices of the points to cluster into lobes and where they came from ('leaf', 'crown', 'all').

    Leaf-on: the leaf points, plus every point off the main branches above the lowest 5 % of the tree:
    leaves the heuristic missed, and the twigs among them, which the lobes bound (VRTree's "lobe-bounded
    twigs"; with given labels too since session 31: the guiding-vector elm, seed 3, with labels, covered
    94 % of its leaf points, the scan's leaves beside its twigs lost in the downsampling).
    Leaf-off trees (fewer than ``leaf_off_fraction`` leaf points) cluster that crown alone. Points of the
    ``bare`` trunk (N,) bool join a leaf-on tree's foliage only as leaf points (guessed labels call them
    wood: ``decompose``; given labels are believed: leaves growing from the trunk stay).
    """
    n_lobes = o.counts()[1]
    leaf = labels == LEAF
    crown = off_main & (pts[:, 2] > CROWN_BASE)
    if leaf.sum() >= max(4 * n_lobes, o.leaf_off_fraction * len(pts)):
        return np.flatnonzero(leaf | (crown & ~bare)), "leaf"
    if crown.sum() >= 4 * n_lobes:
        return np.flatnonzero(crown), "crown"
    return np.arange(len(pts)), "all"


def centre_grid(pts: np.ndarray, r_trunk: float) -> BoxGrid:
    """The grid whose 3x3x3 boxes (+-max(CENTRE_RADIUS, 1.5 r_trunk)) centre branch vertices."""
    return BoxGrid(pts, max(CENTRE_RADIUS, 1.5 * r_trunk) / 1.5)


def main_branches(pts: np.ndarray, lab: np.ndarray, g: Graph, root: int, grid: BoxGrid, tau: float,
                  o: DecomposeOptions, tree: cKDTree | None = None):
    """Algorithm 1 step 1 on the shortest paths (edges touching a leaf point ``leaf_edge_cost`` times longer)
    to FPS endpoints, then every main branch smoothed (smooth.py, ours). ``merge.select_mains`` may keep
    fewer than N_m paths when no candidate reaches 2 steps beyond the kept ones.

    A path that falls more than ``HOOK_DROP`` of the height below a point it reached before is routed
    again on ``graph.gap_graph`` (every scan gap costs the same per metre), and the new path replaces
    it if it falls less.
    """
    adj = g.adjacency if o.edge_power == 1.0 else g.adjacency.power(o.edge_power)
    cost = np.where(lab == LEAF, o.leaf_edge_cost, 1.0)
    _, pred = shortest_paths(weighted(adj, cost), root)
    ends = farthest_points(pts, o.fps_candidates + 1, root)
    ends = [int(e) for e in ends[ends != root][: o.fps_candidates]]
    paths = branch_paths(ends, pred, pts, grid, o.step)
    hooked = [i for i, p in enumerate(paths) if drop(p) > HOOK_DROP * float(np.ptp(pts[:, 2]))]
    gaps = gap_graph(pts, g, o.query_radius) if hooked else None
    if gaps is not None:
        _, pred2 = shortest_paths(weighted(gaps if o.edge_power == 1.0 else gaps.power(o.edge_power), cost), root)
        for i, p in zip(hooked, branch_paths([ends[i] for i in hooked], pred2, pts, grid, o.step)):
            paths[i] = p if drop(p) < drop(paths[i]) else paths[i]
    order = select_mains(paths, o.counts()[0], tau, o.step, o.selection_weight())
    return smooth_branchset(merge_mains(paths, order, tau, o.resample, o.sc_bins), tree)


def decompose(points: np.ndarray, options: DecomposeOptions = DecomposeOptions(),
              progress: ProgressFn = no_progress, labels: np.ndarray | None = None) -> Decomposition:
    """Decompose ``points`` (N, 3) (optional ``labels`` (N,) WOOD/LEAF) into a whole-tree HBL.

    Raises ``InputError`` for clouds that hold no usable single tree.
    """
    o = options
    rng = np.random.default_rng(o.seed)
    clock = _Clock(progress)
    prep = prepare(points, o, rng, labels)
    pts = prep.points
    root = int(np.argmin(np.linalg.norm(pts, axis=1)))
    clock.lap("prepare")
    g = knn_graph(pts, o.k, o.query_radius)
    r_trunk = trunk_radius(pts)
    tau = max(o.merge_threshold, r_trunk)
    grid = centre_grid(pts, r_trunk)
    clock.lap("graph")
    lab = prep.labels if prep.labels is not None else separate(pts, g.neighbours, o.leaf_dimension)
    clock.lap("separate")
    tree = g.tree  # the graph's KD-tree of the same points: built once
    mains = main_branches(pts, lab, g, root, grid, tau, o, tree)
    clock.lap("mains")
    bare = bare_trunk(pts, mains)
    if prep.labels is None:  # guessed labels: the bare trunk is wood
        lab = np.where(bare, WOOD, lab).astype(np.uint8)
    off_main = main_clearance(mains, pts, tau, tree, r_trunk)
    fol, source = foliage_points(lab, pts, off_main, o, bare)
    k_lab, centres = kmeans(pts[fol], o.counts()[1], rng)
    groups = [fol[k_lab == j] for j in range(len(centres))]
    sources = zone_sources(pts, np.concatenate(groups))
    zone = zones(pts, groups, sources)
    clock.lap("lobes")
    lobes, pred2, rerouted, tunnelled = make_lobes(groups, centres, pts, g.adjacency, root, zone, mains, grid,
                                                   tau, o, tree=tree)
    clock.lap("secondary")
    lobe_of = np.full(len(pts), -1, np.int32)
    lobe_of[fol] = k_lab
    said = np.zeros_like(lab) if o.leaf_off else lab  # declared leaf-off: all wood, the geometry as guessed
    stats = {
        "points": len(pts), "height": WORK_HEIGHT / prep.scale, "leaf_points": int((said == LEAF).sum()),
        "ground_removed": prep.ground_removed, "repeated": prep.repeats.as_stats(), "strays": prep.strays,
        "apart": prep.apart,
        "trunk_columns": [c._asdict() | {"foot": list(c.foot)} for c in prep.columns], "width_ratio": width_ratio(pts),
        "labels": "leaf-off" if o.leaf_off else "given" if prep.labels is not None else "guessed",
        "components": g.components, "bridges": g.bridges, "foliage_source": source,
        "main_branches": len(mains.segments), "lobes": len(lobes), "rerouted": rerouted,
        "tunnelled": tunnelled,
        "alpha_shapes": sum(lb.alpha for lb in lobes), "hull_fallbacks": sum(not lb.alpha for lb in lobes),
        "merge_threshold": tau,
    } | ({"fine_wood_points": int((lab == LEAF).sum())} if o.leaf_off else {})
    d = Decomposition(None, pts, said, root, pred2, mains, tuple(lobes), lobe_of, r_trunk, o,  # type: ignore[arg-type]
                      prep.scale, prep.root_scan, prep.source_index, g.adjacency, clock.timing, stats, tau, grid,
                      sources)
    d = replace(d, hbl=build_hbl(d))
    clock.lap("hbl")
    return d
