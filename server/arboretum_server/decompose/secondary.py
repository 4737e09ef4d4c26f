"""Secondary branches (VRTree section 3.4, Fig. 4 c-e): shortest paths to the lobe centres, Algorithm 1
step 2, and a repair that keeps a secondary branch out of lobes it does not feed.

Routing: the shortest paths run on the kNN graph with every edge that touches a lobe's zone (points
within ``ZONE_RADIUS`` of a lobe's points) made ``ZONE_COST`` times longer, so a path reaches its lobe
along the wood and enters foliage only near its target. A secondary branch that still has a vertex
inside a foreign lobe's hull is routed again on a graph where foreign zones cost ``FOREIGN_COST`` times
more (the same path as a full Dijkstra run, ties broken by node number: ``graph.shortest_path_to``; since
session 24 one run per ``make_lobes`` call on the graph where every zone is foreign, repaired for each
offender over its own zone's edges, ``graph.path_after_cut``; before, one run per offender, bounded by
the length of its first path on that graph). If even that path crosses (the only wood to the lobe runs
through another lobe), the secondary branch becomes a straight segment from the nearest main-branch
vertex whose segment to the lobe centre stays clear (a deviation from the paper, which has no such
guarantee), else a two-piece one through one of the lobe's own points. If none clears because the main
branches there run inside foreign lobes (an alpha shape fills the gap where a main branch passes through
its foliage: the pine's lobes wrap its trunk), those lobes are rebuilt with the main branches carved out
(``unwrap``) and both repairs are tried again (a piece of a split lobe whose straight repair crosses first
tries ``tunnel.along``, a branch along the split lobe's own; session 25); if still none clears, the last step of ``make_lobes``
(``tunnel.behind``) carves the branch a way through the other new lobes, or moves its lobe's centre.

Every secondary branch is smoothed (smooth.py, ours) with its connection point on the main branch and its
tip at the lobe centre fixed; where the smoothed curve would enter a foreign lobe and the unsmoothed
path does not, the unsmoothed path smoothed with half the displacement limits is taken if it stays
clear, else the unsmoothed path (``clear_smooth``), so smoothing never adds a crossing.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from .blockers import forget_blockers
from .carve import part_overlaps, remember_plain, unwrap
from .clear import bent_fallback, boxes, foreign, inside_foreign, straight_fallback
from .graph import path_after_cut, paths_to, query, shortest_paths, weighted
from .grid import BoxGrid
from .lobes import plain_hulls
from .memo import ArrayMemo
from .merge import (
    BranchSet,
    centre_paths,
    main_references,
    merge_secondaries,
    resample_step,
)
from .options import DecomposeOptions
from .smooth import smooth_polylines, vertex_limits
from .state import LobeState
from .tunnel import along, behind

ZONE_RADIUS = 0.015
"""Points within this distance (0.8 m frame) of a lobe's points belong to its zone."""
ZONE_COST = 10.0
"""Edge-length factor inside any lobe zone for the shared secondary routing."""
FOREIGN_COST = 1000.0
"""Edge-length factor inside foreign lobe zones when a secondary branch is routed again."""


def zone_sources(pts: np.ndarray, members: np.ndarray) -> np.ndarray:
    """(N,) int64: for each point, the one of ``members`` (indices into ``pts``) nearest it within
    ZONE_RADIUS, -1 for none. Lobes trade points but keep their union (merge, split), so this outlives them;
    the members are sorted first, so exact ties (duplicate points) go the same way however they are listed."""
    src = np.full(len(pts), -1, np.int64)
    if len(members) == 0:
        return src
    members = np.sort(members)
    d, i = query(cKDTree(pts[members]), pts, distance_upper_bound=ZONE_RADIUS)
    hit = np.isfinite(d)
    src[hit] = members[i[hit]]
    return src


def zones(pts: np.ndarray, groups: list[np.ndarray], sources: np.ndarray | None = None) -> np.ndarray:
    """(N,) int32: the lobe whose points lie nearest each point within ZONE_RADIUS, -1 for none.
    ``sources``: ``zone_sources`` of the groups' union, when known."""
    if sources is None:
        sources = zone_sources(pts, np.concatenate(groups).astype(np.int64) if groups else np.zeros(0, np.int64))
    owner = np.full(len(pts), -1, np.int32)
    for j, g in enumerate(groups):
        owner[g] = j
    return np.where(sources >= 0, owner[np.maximum(sources, 0)], -1).astype(np.int32)


def branch_paths(nodes: list[int], pred: np.ndarray, pts: np.ndarray, grid: BoxGrid, step: float) -> list[np.ndarray]:
    """Shortest paths root -> each node, resampled at ``step`` and centred in the cloud."""
    return _centred([pts[p] for p in paths_to(pred, nodes)], grid, step)  # pred read in place (no list of 1M)


def _centred(paths: list[np.ndarray], grid: BoxGrid, step: float) -> list[np.ndarray]:
    """The graph ``paths`` (node positions (M, 3) each) resampled at ``step``, centred in the cloud and resampled
    again (``branch_paths``)."""
    raw = [resample_step(p, step) for p in paths]
    return [resample_step(p, step) for p in centre_paths(raw, grid)]


def _unwrapped_fallback(lobes: list[LobeState], j: int, mains: BranchSet, pts: np.ndarray, radius: float,
                        box: tuple[np.ndarray, np.ndarray]):
    """The straight or bent repair for lobe ``j`` after ``unwrap``; (route or None, lobe boxes).

    Skipped when the lobe's centre lies inside a foreign lobe (no route ends clear: a lobe inserted
    among another's points); the carving is undone when it does not clear the lobe after all.
    """
    if inside_foreign(lobes, j, lobes[j].centre[None], box)[0]:
        return None, box
    before = list(lobes)
    if not unwrap(lobes, j, mains, pts, radius):
        return None, box
    fallback = straight_fallback(lobes, j, mains) or bent_fallback(lobes, j, mains, pts)
    if fallback is None:
        lobes[:] = before
    return fallback, boxes(lobes)


def clear_smooth(lobes: list[LobeState], j: int, raw: np.ndarray, smooth: np.ndarray, tol: float,
                 box: tuple[np.ndarray, np.ndarray], tree: cKDTree) -> np.ndarray | None:
    """Lobe ``j``'s secondary branch kept out of foreign lobes: ``smooth`` if it stays clear, else ``raw``
    smoothed with half the displacement limits, else ``raw``, whichever stays clear first (smoothing never
    adds a crossing); None if even ``raw`` crosses (route again)."""
    if not foreign(lobes, j, smooth, tol, box):
        return smooth
    if foreign(lobes, j, raw, tol, box):
        return None
    half = smooth_polylines([raw], 0.5 * np.asarray(vertex_limits([raw], tree)))[0]
    return raw if foreign(lobes, j, half, tol, box) else half


def _finish(seg: np.ndarray, centre: np.ndarray) -> np.ndarray:
    return seg if np.linalg.norm(seg[-1] - centre) <= 1e-9 else np.vstack([seg, centre])


def make_lobes(groups: list[np.ndarray], centres: np.ndarray, pts: np.ndarray, adjacency: csr_matrix,
               root: int, zone: np.ndarray, mains: BranchSet, grid: BoxGrid, tau: float,
               o: DecomposeOptions, others: tuple[LobeState, ...] = (),
               hulls: tuple[LobeState | None, ...] = (), tree: cKDTree | None = None,
               split: tuple[np.ndarray, int, int] | None = None) -> tuple[list[LobeState], np.ndarray, int, int]:
    """Lobes over the point-index ``groups`` with hulls and routed, merged secondary branches.

    ``others`` are lobes kept from before (zone ids 0..len(others)-1; the new lobes follow them).
    ``hulls[i]``, when given, is a lobe over ``groups[i]`` whose hull the group keeps (a kept lobe whose
    branch is routed again); other groups get their plain hull. ``tree``: a KD-tree of ``pts`` (None:
    built here). ``split``: the branch (segment, parent, vertex) of the lobe the new lobes were split from
    (``refine.split_lobe``): a new lobe whose rerouted branch and straight repair cross takes a branch along it
    (``tunnel.along``) before the bent and carved repairs.
    Returns every lobe (``others`` first, then the new ones; any of them may come back with the main
    branches carved out, see ``unwrap``, or carved round a new lobe whose centre it buried, see
    ``part_overlaps``, which may instead move that new lobe's centre onto one of its own points), the
    routing predecessors (N,), the number of branches routed again and the number no repair cleared,
    which ``tunnel.behind`` gave a way carved through the other new lobes or a moved centre (a branch
    stays crossing only when neither clears it).
    """
    forget_blockers()  # the repairs' known blockers (blockers.Blockers) live for one call
    lobes = list(others) + _hulled(groups, centres, pts, hulls, o.alpha_radius)
    part_overlaps(lobes, len(others), mains, pts, o.alpha_radius)
    centres = [lb.centre for lb in lobes[len(others):]]
    _, pred = shortest_paths(weighted(adjacency, np.where(zone >= 0, ZONE_COST, 1.0)), root)
    targets = [int(g[np.argmin(np.linalg.norm(pts[g] - c, axis=1))]) for g, c in zip(groups, centres)]
    refs = main_references(mains, o.resample, o.sc_bins)
    merged = merge_secondaries(branch_paths(targets, pred, pts, grid, o.step), mains, tau, o.resample, o.sc_bins,
                               refs)
    raw = [_finish(seg, c) for (seg, _, _), c in zip(merged, centres)]
    tree = cloud_tree(pts) if tree is None else tree  # the graph's, when given: 0.3 s of a million points
    smooth = smooth_polylines(raw, vertex_limits(raw, tree))
    for j, (seg, (_, parent, pv)) in enumerate(zip(smooth, merged), start=len(others)):
        lobes[j] = replace(lobes[j], segment=seg, parent=parent, parent_vertex=pv)
    rerouted = 0
    box = boxes(lobes)
    route = _Route(pts, adjacency, root, zone, mains, grid, tau, o, refs, tree, {}, pred, split, len(others))
    for j in range(len(others), len(lobes)):
        seg = clear_smooth(lobes, j, raw[j - len(others)], lobes[j].segment, o.step / 2, box, tree)
        if seg is not None:
            lobes[j] = replace(lobes[j], segment=seg)
            continue
        if not rerouted:  # the first reroute: route with it every later lobe that would be routed again now
            later = [k for k in range(j + 1, len(lobes))
                     if _crosses(lobes, k, raw[k - len(others)], lobes[k].segment, o.step / 2, box)]
            _batch_routes(lobes, route, [j, *later], [targets[k - len(others)] for k in (j, *later)])
        rerouted += 1
        box = _reroute(lobes, j, targets[j - len(others)], route, box)
    asked = behind(lobes, len(others), pts, mains, o)
    forget_blockers()
    return lobes, pred, rerouted, asked


_TREES = ArrayMemo()
"""A KD-tree of each point array, while the array lives: every refinement's ``make_lobes`` (and each of its
routing rounds) built one of the same 12,000 points again (2-4 ms)."""


def cloud_tree(pts: np.ndarray) -> cKDTree:
    """``cKDTree(pts)``, built once per ``pts`` array (the same tree, so the same answers, as a new one).
    The decomposition's and the refinements' points are never changed in place; an array that was would
    get its old tree back."""
    hit = _TREES.get(pts)
    return hit if hit is not None else _TREES.put(pts, cKDTree(pts))


def _hulled(groups: list[np.ndarray], centres: np.ndarray, pts: np.ndarray, hulls: tuple[LobeState | None, ...],
            alpha_radius: float) -> list[LobeState]:
    """A lobe (no branch yet) per group: the hull of ``hulls[i]`` when given, else the group's plain hull (all of
    these built at once, ``plain_hulls``: on every core; each remembered here, in group order)."""
    olds = [hulls[i] if i < len(hulls) else None for i in range(len(groups))]
    todo = [i for i, old in enumerate(olds) if old is None]
    built = dict(zip(todo, plain_hulls([pts[groups[i]] for i in todo], alpha_radius)))
    out = []
    for i, (g, c, old) in enumerate(zip(groups, centres, olds)):
        if old is not None:
            verts, faces, used_alpha, steps = old.hull_vertices, old.hull_faces, old.alpha, old.steps
        else:
            verts, faces, used_alpha, steps, tet = built[i]
            remember_plain(g, tet)
        out.append(LobeState(g, np.asarray(c, np.float64), verts, faces, used_alpha, np.zeros((0, 3)), -1, -1,
                             steps))
    return out


class _Route(NamedTuple):
    """What routing a secondary branch again needs (the arguments of ``make_lobes``, and its main references
    and KD-tree of the points)."""

    pts: np.ndarray
    adjacency: csr_matrix
    root: int
    zone: np.ndarray
    mains: BranchSet
    grid: BoxGrid
    tau: float
    o: DecomposeOptions
    refs: tuple
    tree: cKDTree
    cache: dict
    """The per-edge zone weights of ``foreign_graph``, built at the first reroute of a ``make_lobes`` call, and
    each rerouted lobe's own zone edges (``_own_entries``), the distances on the graph where every zone is
    foreign (``_reroute_path``), the reweighted graph of ``foreign_graph`` and the routes of the lobes
    routed again in one batch at the first reroute (``_batch_routes``), by lobe, until their ``_reroute``."""
    pred: np.ndarray
    """(N,) the shared routing's predecessors."""
    split: tuple[np.ndarray, int, int] | None = None
    """The split lobe's branch (segment, parent, vertex) that its pieces' branches may run along, else None."""
    n_kept: int = 0
    """How many lobes were kept from before (the new ones follow them)."""


def _edge_zones(adjacency: csr_matrix, zone: np.ndarray) -> tuple[csr_matrix, np.ndarray, np.ndarray]:
    """The graph in CSR form, its edge lengths with every zone edge ``FOREIGN_COST`` dearer, and per edge
    the lobe whose zone holds all its zoned ends (-1 for none or several). Built once per ``make_lobes``:
    reweighting the whole graph again for each rerouted branch repeated the same gathers."""
    adj = adjacency.tocsr()
    rows = np.repeat(np.arange(adj.shape[0]), np.diff(adj.indptr))
    zr, zc = zone[rows], zone[adj.indices]
    hi = np.maximum(zr, zc)
    dear = adj.data * np.where(hi >= 0, FOREIGN_COST, 1.0)
    one = ((zr == hi) | (zr < 0)) & ((zc == hi) | (zc < 0))
    return adj, dear, np.where(one, hi, -1)


def foreign_graph(r: _Route, j: int) -> csr_matrix:
    """``weighted(adjacency, cost)`` for lobe ``j``'s reroute (zone ``j`` edges ``ZONE_COST`` longer, other
    zones' ``FOREIGN_COST``), the same weights bit for bit, from the edge zones built once per call (an edge
    takes its dearer end's cost, as in ``weighted``: this relies on 1 <= ``ZONE_COST`` <= ``FOREIGN_COST``).
    One graph per call (``r.cache["graph"]``), its entries set for lobe ``j`` and those set for the lobe asked
    before put back (session 28: a copy of every edge weight and a new matrix per reroute, 20 a split into 20),
    so it holds lobe ``j``'s weights until ``foreign_graph`` is asked for another lobe of the same call."""
    adj, dear, _ = _edges(r)
    if "graph" not in r.cache:
        r.cache["graph"] = [csr_matrix((dear.copy(), adj.indices, adj.indptr), shape=adj.shape), None]
    graph, was = r.cache["graph"]
    if was is not None:
        graph.data[was] = dear[was]
    own = _own_entries(r, j)
    graph.data[own] = adj.data[own] * ZONE_COST
    r.cache["graph"][1] = own
    return graph


def _own_entries(r: _Route, j: int) -> np.ndarray:
    """``np.flatnonzero(owner == j)`` for the edge owners of ``_edge_zones``: the entries of lobe ``j``'s own zone
    edges, found once per lobe and ``make_lobes`` call (``r.cache["owned"]``): ``foreign_graph`` and
    ``_reroute_path`` each scanned every edge for them."""
    owned = r.cache.setdefault("owned", {})
    if j not in owned:
        owned[j] = np.flatnonzero(_edges(r)[2] == j)
    return owned[j]


def _edges(r: _Route) -> tuple:
    """``_edge_zones`` of the call's graph, built at its first reroute (``r.cache["edges"]``)."""
    if "edges" not in r.cache:
        r.cache["edges"] = _edge_zones(r.adjacency, r.zone)
    return r.cache["edges"]


def _reroute_path(r: _Route, j: int, graph: csr_matrix, target: int) -> np.ndarray:
    """Node indices root -> ``target`` of lobe ``j``'s reroute on ``graph`` (``foreign_graph(r, j)``): the path
    ``graph.shortest_path_to`` gives, from the distances on the graph where every zone is foreign (one full
    Dijkstra per ``make_lobes`` call, kept in ``r.cache``) repaired over lobe ``j``'s own zone edges
    (``graph.path_after_cut``)."""
    adj, dear, _ = _edges(r)
    if "base" not in r.cache:
        r.cache["rows"] = np.repeat(np.arange(adj.shape[0]), np.diff(adj.indptr))
        r.cache["base"] = shortest_paths(csr_matrix((dear, adj.indices, adj.indptr), shape=adj.shape), r.root)[0]
    return path_after_cut(graph, r.cache["rows"], r.cache["base"], _own_entries(r, j), r.root, target)


def _crosses(lobes: list[LobeState], j: int, raw: np.ndarray, smooth: np.ndarray, tol: float,
             box: tuple[np.ndarray, np.ndarray]) -> bool:
    """True if ``clear_smooth`` would give None (both ``smooth`` and ``raw`` enter a foreign lobe): lobe ``j`` is
    routed again."""
    return foreign(lobes, j, smooth, tol, box) and foreign(lobes, j, raw, tol, box)


def _routes(r: _Route, centres: list[np.ndarray], js: list[int], targets: list[int]) -> list[tuple]:
    """(target, centre, segment, smoothed segment, parent, vertex) of lobes ``js``' branches routed again round
    the foreign lobes (``_reroute``'s route before its repairs), all at once: each path is centred, merged,
    finished at its lobe's centre and smoothed by itself (every step works path by path, point by point), so
    the same arrays as one call per lobe; one call of each for all of them (session 26: a split into 20
    reroutes all 20 pieces, one ``merge_secondaries`` call each)."""
    o = r.o
    paths = _centred([r.pts[_reroute_path(r, j, foreign_graph(r, j), t)] for j, t in zip(js, targets)], r.grid,
                     o.step)
    merged = merge_secondaries(paths, r.mains, r.tau, o.resample, o.sc_bins, r.refs)
    segs = [_finish(seg, c) for (seg, _, _), c in zip(merged, centres)]
    smoothed = smooth_polylines(segs, vertex_limits(segs, r.tree))
    return [(t, c, seg, sm, parent, pv) for t, c, seg, sm, (_, parent, pv) in zip(targets, centres, segs, smoothed,
                                                                                  merged)]


def _batch_routes(lobes: list[LobeState], r: _Route, js: list[int], targets: list[int]) -> None:
    """``_routes`` of lobes ``js`` kept in ``r.cache["routes"]`` for their ``_reroute`` (which routes a lobe by
    itself when its entry is missing or its target or centre changed since)."""
    found = _routes(r, [lobes[j].centre for j in js], js, targets)
    r.cache["routes"] = dict(zip(js, found))


def _reroute(lobes: list[LobeState], j: int, target: int, r: _Route, box):
    """Lobe ``j``'s branch routed again round the foreign lobes (zones ``FOREIGN_COST`` dearer), and when it
    still enters one, the straight, bent and carved repairs in turn (``lobes[j]`` replaced in place; the
    lobes' boxes returned, new when a carving changed a hull).

    A piece of a split lobe (``r.split``) whose straight repair crosses first tries a branch along the split
    lobe's own (``tunnel.along``), which otherwise ``refine._along_split`` gives it after every repair of
    ``make_lobes`` failed. Session 25 (helper-180; the bench's 8 splits and 783 probe splits of 7 trees): 451
    of 16,580 pieces (106 splits) changed, their branches 12.3 -> 11.4 cm long (median) and their sharpest
    bend 63.7 -> 37.0 degrees (mean), 67 worse and 247 better by rules set before; no crossing either way,
    leaf cover 1.0 in all 202 of the pine's splits; the bench's 8 splits at 0.57-0.88 of the CPU before."""
    lb, o = lobes[j], r.o
    found = r.cache.get("routes", {}).pop(j, None)
    if found is None or found[0] != target or not np.array_equal(found[1], lb.centre):
        found = _routes(r, [lb.centre], [j], [target])[0]
    seg, smoothed, parent, pv = found[2:]
    seg = clear_smooth(lobes, j, seg, smoothed, o.step / 2, box, r.tree)
    if seg is None:
        fallback = straight_fallback(lobes, j, r.mains)
        if fallback is None and r.split is not None and along(lobes, r.n_kept, j, r.split, r.pts, o):
            return boxes(lobes)  # along may have carved other pieces
        fallback = fallback or bent_fallback(lobes, j, r.mains, r.pts)
        if fallback is None:
            fallback, box = _unwrapped_fallback(lobes, j, r.mains, r.pts, o.alpha_radius, box)
        seg, parent, pv = fallback or (smoothed, parent, pv)
    lobes[j] = replace(lb, segment=seg, parent=parent, parent_vertex=pv)
    return box
