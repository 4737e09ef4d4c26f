"""Guiding-vector trees (Xu and Mould 2015, "Procedural Tree Modeling with Guiding Vectors").

A tree is a union of least-cost paths in an irregular graph: Poisson-disc nodes in a box (``poisson``),
linked in a Yao graph (``yao``); Dijkstra's algorithm with lazy guiding vectors (``paths``, ``fields``)
from the source to endpoints (``endpoints``); repeated 4-5 times with the tree so far as the source.
``grow_guiding`` returns the ground truth (``arboretum_library.truth.TreeTruth``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from arboretum_library.progress import ProgressFn, no_progress
from arboretum_library.truth import TreeTruth

from .endpoints import RULES, Volume, rule_ok, surface_candidates, volume_candidates
from .fields import INCREMENTAL, Rotation, field_angles, incremental_angles
from .paths import CsrGraph, Search, lazy_search
from .poisson import poisson_disc, spacing_for_count
from .skeleton import skeleton_truth
from .yao import YaoGraph, yao_graph

RULE_OVERSAMPLE = 10
"""With the hanging or upward rule, this many candidates per endpoint are searched, then filtered."""


@dataclass(frozen=True)
class Iteration:
    """One iteration of path planning: its guiding-vector rule and its endpoints."""

    rotation: Rotation = field(default_factory=Rotation)
    """The guiding-vector rule (alpha_1, alpha_2, h_0, R, theta, or a field)."""
    endpoints: int = 100
    """Endpoint count (the endpoint density of section 3.2.4)."""
    volume: Volume | None = None
    """Early placement: endpoints drawn from this volume; None: late placement (k, t)."""
    k: int = 4
    """k: late endpoints lie exactly k hops out from the tree so far."""
    t: float = 0.6
    """t: outermost fraction (by hops from the root) of the k-hop surface that may hold endpoints."""
    rule: str = "none"
    """none, hanging (endpoints lower than their source node) or upward (higher)."""

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"Iteration.rule must be one of {RULES}, got {self.rule!r}")


@dataclass(frozen=True)
class GuidingOptions:
    """Parameters of one guiding-vector tree (metres, degrees)."""

    width: float = 12.0
    """Graph box extent along X and Y, centred on the root."""
    height: float = 12.0
    """Graph box extent along Z, from the root up."""
    nodes: int = 60_000
    """Approximate graph node count (the paper's trees use 150,000); sets the disc size."""
    sectors: int = 14
    """Yao sectors per node in 3D: 8 (octants), 14 or 26 cones (see ``yao``)."""
    knn: int = 24
    """Nearest neighbours searched per node when building the Yao graph."""
    iterations: tuple[Iteration, ...] = ()
    """The iterations, in order (typically 4-5)."""
    tip_radius: float = 0.004
    """Branch radius at every tip; the pipe model sets the others."""
    pipe_exponent: float = 2.0
    """Pipe model exponent e: r_parent^e = sum r_child^e (2 = da Vinci's area rule)."""
    leaf_size: float = 0.12
    """Leaf card length."""
    leaves_per_node: int = 2
    """Leaves on each leaf-bearing node."""
    leaf_depth: int = 2
    """Nodes within this many hops of a tip (on branches of order >= 1) bear leaves."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "iterations", tuple(self.iterations))


@dataclass
class TreeState:
    """The tree so far, over all graph nodes."""

    root: int
    """The root node."""
    in_tree: np.ndarray
    """(N,) bool: node is in the tree."""
    parent: np.ndarray
    """(N,) int64: parent in the tree, -1 for the root and nodes outside."""
    root_hops: np.ndarray
    """(N,) int64: edges from the root along the tree."""
    generation: np.ndarray
    """(N,) int64: the iteration that added the node (0 for the root), -1 outside."""
    theta: np.ndarray
    """(N,) float64: guiding vector polar angles."""
    phi: np.ndarray
    """(N,) float64: guiding vector azimuths."""


def build_graph(opts: GuidingOptions, rng: np.random.Generator) -> tuple[YaoGraph, int]:
    """The Yao graph over Poisson-disc nodes, and the root node (nearest the box's bottom centre)."""
    half = opts.width / 2
    lo, hi = np.array([-half, -half, 0.0]), np.array([half, half, opts.height])
    r = spacing_for_count(hi - lo, opts.nodes)
    pts = poisson_disc(lo, hi, r, rng)
    root = int(np.argmin(np.linalg.norm(pts - [0.0, 0.0, 0.0], axis=1)))
    return yao_graph(pts, opts.sectors, opts.knn), root


def grow_paths(
    g: YaoGraph,
    root: int,
    opts: GuidingOptions,
    rng: np.random.Generator,
    progress: ProgressFn = no_progress,
    search: Callable[..., Search] = lazy_search,
) -> TreeState:
    """Run the iterations of path planning from ``root``; returns the tree over the graph nodes.

    ``search`` is ``paths.lazy_search``, or ``paths.reference_search`` (the same trees, slowly).
    """
    n = len(g.points)
    st = TreeState(root, np.zeros(n, bool), np.full(n, -1), np.zeros(n, np.int64), np.full(n, -1),
                   np.zeros(n), np.zeros(n))  # fmt: skip
    st.in_tree[root], st.generation[root] = True, 0
    cg = CsrGraph.of(g)
    for i, it in enumerate(opts.iterations):
        progress(i, len(opts.iterations), f"guiding vectors: iteration {i + 1}")
        _iterate(g, cg, st, it, i, rng, search)
    progress(len(opts.iterations), len(opts.iterations), "guiding vectors: done")
    return st


def _iterate(
    g: YaoGraph, cg: CsrGraph, st: TreeState, it: Iteration, gen: int, rng: np.random.Generator,
    search: Callable[..., Search],
) -> None:  # fmt: skip
    pts, root = g.points, g.points[st.root]
    if it.volume is not None:
        cand = volume_candidates(pts, st.in_tree, it.volume)
    else:
        cand = surface_candidates(g.neighbours, st.in_tree, st.root_hops, it.k, it.t, rng)
    cand = rng.permutation(cand)
    targets = cand[: it.endpoints * (1 if it.rule == "none" else RULE_OVERSAMPLE)]
    if len(targets) == 0:
        return
    sources = np.flatnonzero(st.in_tree)
    theta, phi = st.theta.copy(), st.phi.copy()
    if it.rotation.kind in INCREMENTAL:
        near, far, h0 = incremental_angles(it.rotation, pts, root, rng)
    else:  # a directly set field: every vector is known before the search
        theta, phi = field_angles(it.rotation, pts, root)
        near, far, h0 = None, None, 0
    res = search(cg, sources, theta, phi, near, far, h0, targets)
    targets = targets[res.done[targets]]
    ok = rule_ok(it.rule, pts[targets, 2], pts[res.origin[targets], 2])
    _add_paths(st, res, targets[ok][: it.endpoints], gen)


def _add_paths(st: TreeState, res, ends: np.ndarray, gen: int) -> None:
    in_tree = st.in_tree.tolist()
    par = res.parent.tolist()
    new = []
    for e in ends.tolist():
        u = e
        while not in_tree[u]:
            in_tree[u] = True
            new.append(u)
            u = par[u]
    new = np.array(new, dtype=np.int64)
    if len(new) == 0:
        return
    st.in_tree[new] = True
    st.parent[new] = res.parent[new]
    st.root_hops[new] = st.root_hops[res.origin[new]] + res.hops[new]
    st.generation[new] = gen
    st.theta[new], st.phi[new] = res.theta[new], res.phi[new]


def grow_guiding(
    opts: GuidingOptions, seed: int, species: str = "custom", progress: ProgressFn = no_progress
) -> TreeTruth:
    """Grow one guiding-vector tree; the same options and seed give the same tree."""
    rng = np.random.default_rng(seed)
    g, root = build_graph(opts, rng)
    st = grow_paths(g, root, opts, rng, progress)
    params = dataclasses.asdict(opts)
    params["disc_radius"] = spacing_for_count(
        np.array([opts.width, opts.width, opts.height]), opts.nodes
    )
    params["graph_nodes"] = len(g.points)
    return skeleton_truth(
        g.points, st, opts, rng, model="guiding", species=species, seed=seed, params=params
    )


def path_stretch(points: np.ndarray, parent: np.ndarray, tip: int, start: int) -> float:
    """Path length / straight distance between ``start`` and ``tip`` along ``parent`` links."""
    length, u = 0.0, tip
    while u != start:
        length += float(np.linalg.norm(points[u] - points[parent[u]]))
        u = int(parent[u])
    return (
        length / max(float(np.linalg.norm(points[tip] - points[start])), 1e-12)
        if length
        else math.inf
    )
