"""Secondary branches (VRTree section 3.4, Fig. 4 c-e): shortest paths to the lobe centres, Algorithm 1
step 2, and a repair that keeps a secondary branch out of lobes it does not feed.

Routing: the shortest paths run on the kNN graph with every edge that touches a lobe's zone (points
within ``ZONE_RADIUS`` of a lobe's points) made ``ZONE_COST`` times longer, so a path reaches its lobe
along the wood and enters foliage only near its target. A secondary branch that still has a vertex
inside a foreign lobe's hull is routed again on a graph where foreign zones cost ``FOREIGN_COST`` times
more (one extra Dijkstra per offender). If even that path crosses (the only wood to the lobe runs
through another lobe), the secondary branch becomes a straight segment from the nearest main-branch
vertex whose segment to the lobe centre stays clear (a deviation from the paper, which has no such
guarantee), else a two-piece one through one of the lobe's own points. If none clears because the main
branches there run inside foreign lobes (an alpha shape fills the gap where a main branch passes through
its foliage: the pine's lobes wrap its trunk), those lobes are rebuilt with the main branches carved out
(``unwrap``) and both repairs are tried again; if still none clears, the crossing path is kept.

Every secondary branch is smoothed (smooth.py, ours) with its connection point on the main branch and its
tip at the lobe centre fixed; where the smoothed curve would enter a foreign lobe and the unsmoothed
path does not, the unsmoothed path is kept, so smoothing never adds a crossing.
"""

from __future__ import annotations

import weakref
from dataclasses import replace

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from .graph import path_to, shortest_paths, weighted
from .grid import BoxGrid
from .lobes import RADIUS_STEPS, Tetrahedra, carved_hull, inside, plain_hull, plain_steps
from .merge import (
    BranchSet,
    centre_paths,
    main_references,
    merge_secondaries,
    resample_step,
    sample_polylines,
)
from .options import DecomposeOptions
from .smooth import smooth_polylines, vertex_limits
from .state import LobeState

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
    d, i = cKDTree(pts[members]).query(pts, distance_upper_bound=ZONE_RADIUS)
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
    tree = pred.tolist()
    raw = [resample_step(pts[path_to(tree, n)], step) for n in nodes]
    return [resample_step(p, step) for p in centre_paths(raw, grid)]


def boxes(lobes: list[LobeState]) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes (lo (L, 3), hi (L, 3)) of the lobes' hulls."""
    return (np.array([lb.hull_vertices.min(axis=0) for lb in lobes]),
            np.array([lb.hull_vertices.max(axis=0) for lb in lobes]))


def inside_foreign(lobes: list[LobeState], j: int, q: np.ndarray,
                   box: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(M,) bool: which of the points ``q`` (M, 3) lie inside a lobe other than ``j``."""
    lo, hi = box if box is not None else boxes(lobes)
    inbox = ((q[None] > lo[:, None]) & (q[None] < hi[:, None])).all(axis=2)  # (L, M)
    inbox[j] = False
    out = np.zeros(len(q), bool)
    for k in np.flatnonzero(inbox.any(axis=1)):
        sel = np.flatnonzero(inbox[k] & ~out)
        if len(sel):
            lb = lobes[k]
            out[sel] = inside(lb.hull_vertices, lb.hull_faces, q[sel])
    return out


def foreign(lobes: list[LobeState], j: int, seg: np.ndarray, tol: float,
            box: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """True if a vertex of ``seg`` (resampled every ``tol``) lies inside a lobe other than ``j``."""
    return bool(inside_foreign(lobes, j, resample_step(seg, tol), box).any())


def _main_vertices(mains: BranchSet) -> tuple[np.ndarray, np.ndarray]:
    """Every main-branch vertex (V, 3) and its (segment, vertex index) (V, 2)."""
    owner = np.concatenate([np.stack([np.full(len(s), b), np.arange(len(s))], 1) for b, s in enumerate(mains.segments)])
    return np.concatenate(mains.segments), owner


def straight_fallback(lobes: list[LobeState], j: int, mains: BranchSet, tries: int = 64,
                      step: float = 0.005, batch: int = 8) -> tuple[np.ndarray, int, int] | None:
    """A straight secondary branch for lobe ``j`` from the nearest main-branch vertex whose segment to the
    lobe centre stays out of foreign lobes (candidates tested ``batch`` at a time, nearest first), or None."""
    centre = lobes[j].centre
    verts, owner = _main_vertices(mains)
    dist = np.linalg.norm(verts - centre, axis=1)
    order = np.array([i for i in np.argsort(dist)[:tries] if dist[i] > 1e-9], dtype=int)
    box = boxes(lobes)
    for start in range(0, len(order), batch):
        cand = order[start : start + batch]
        q, which = _segment_samples(verts[cand], np.broadcast_to(centre, (len(cand), 3)), step)
        bad = _blocked(lobes, j, q, which, len(cand), box)
        if not bad.all():
            i = int(cand[int(np.argmin(bad))])
            m = max(2, int(np.ceil(dist[i] / 0.01)) + 1)
            seg = verts[i] + np.linspace(0.0, 1.0, m)[:, None] * (centre - verts[i])
            return seg, int(owner[i, 0]), int(owner[i, 1])
    return None


def _blocked(lobes: list[LobeState], j: int, q: np.ndarray, which: np.ndarray, n: int,
             box: tuple[np.ndarray, np.ndarray], stride: int = 4) -> np.ndarray:
    """(n,) bool: segments (samples ``q`` (M, 3) of segment ``which`` (M,)) with a sample inside a lobe
    other than ``j``. Every ``stride``-th sample first: most blocked segments show it there, and only
    the segments still clear are tested at every sample (the same answer, a fraction of the cost)."""
    coarse = np.arange(len(q)) % stride == 0
    bad = np.bincount(which[coarse], weights=inside_foreign(lobes, j, q[coarse], box), minlength=n) > 0
    rest = ~coarse & ~bad[which]
    return bad | (np.bincount(which[rest], weights=inside_foreign(lobes, j, q[rest], box), minlength=n) > 0)


def _segment_samples(a: np.ndarray, b: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ~``step`` along the segments a[i] -> b[i] ((S, 3) each) and the segment of each."""
    counts = np.maximum(2, np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(int) + 1)
    which = np.repeat(np.arange(len(a)), counts)
    first = np.cumsum(counts) - counts
    i = np.arange(len(which)) - first[which]
    t = i * (1.0 / (counts - 1))[which]  # np.linspace(0, 1, count) for each segment, bit for bit
    t[first + counts - 1] = 1.0
    t = t[:, None]
    return a[which] + t * (b[which] - a[which]), which


def bent_fallback(lobes: list[LobeState], j: int, mains: BranchSet, pts: np.ndarray, waypoints: int = 32,
                  tries: int = 48, batch: int = 2, step: float = 0.005) -> tuple[np.ndarray, int, int] | None:
    """A two-piece secondary branch for lobe ``j``: main-branch vertex -> one of the lobe's own points ->
    lobe centre, both pieces clear of foreign lobes. The ``tries`` main vertices nearest the centre that
    lie outside every foreign lobe are tested ``batch`` at a time, nearest first; the first batch with a
    clear route gives the shortest one. None if none has one. For lobes that no straight segment reaches (lobes around a pine's trunk)."""
    centre, box = lobes[j].centre, boxes(lobes)
    members = pts[lobes[j].members]
    w = members[:: max(1, len(members) // waypoints)]
    q, which = _segment_samples(w, np.broadcast_to(centre, w.shape), step)
    w = w[~_blocked(lobes, j, q, which, len(w), box)]
    if not len(w):
        return None
    verts, owner = _main_vertices(mains)
    order = np.argsort(np.linalg.norm(verts - centre, axis=1))
    order = order[~inside_foreign(lobes, j, verts[order], box)][:tries]  # a start in a foreign lobe fails
    for start in range(0, len(order), batch):
        v = np.repeat(order[start : start + batch], len(w))  # every (vertex, waypoint) pair of the batch
        ww = np.tile(w, (len(v) // len(w), 1))
        q, which = _segment_samples(verts[v], ww, step)
        bad = _blocked(lobes, j, q, which, len(v), box)
        if bad.all():
            continue
        length = np.where(bad, np.inf, np.linalg.norm(ww - verts[v], axis=1) + np.linalg.norm(ww - centre, axis=1))
        k = int(np.argmin(length))
        a, b = verts[v[k]], ww[k]
        seg = np.vstack([resample_step(np.stack([a, b]), 0.01), resample_step(np.stack([b, centre]), 0.01)[1:]])
        return seg, int(owner[v[k], 0]), int(owner[v[k], 1])
    return None


def unwrap(lobes: list[LobeState], j: int, mains: BranchSet, pts: np.ndarray, radius: float,
           near: int = 64, step: float = 0.005) -> int:
    """Carve the main branches out of the foreign lobes that enclose one of the ``near`` main-branch
    vertices nearest lobe ``j``'s centre (the starts ``straight_fallback`` tries); returns how many lobes
    changed (``lobes`` is updated in place).

    A lobe's alpha shape (probe radius 7.7 cm at the 0.8 m scale) fills the gap where a main branch runs
    through its foliage, so a secondary branch leaving that main branch starts inside a lobe it does not
    feed (the pine's lobes wrap its trunk). Each such lobe is rebuilt with the main branches (resampled
    every ``step``) within one probe radius of its points as blockers (``lobes.carved_hull``), at most at
    the probe radius its plain alpha shape used: it then reaches up to the wood but not across it, and
    lies inside the hull it replaces, so no other branch starts crossing. Only hulls change (members,
    centres and branches stay); a lobe wrapped round a trunk can lose its own centre to the tunnel. The
    same blockers every time, so carving a lobe again gives the same shape. A lobe whose carved shape is
    not a closed one-piece surface is kept.
    """
    if not mains.segments:
        return 0
    verts = _main_vertices(mains)[0]
    near_pts = verts[np.argsort(np.linalg.norm(verts - lobes[j].centre, axis=1))[:near]]
    wood = sample_polylines(mains.segments, step)
    changed = 0
    for k in range(len(lobes)):
        lb = lobes[k]
        if k == j:
            continue
        lo, hi = lb.hull_vertices.min(axis=0), lb.hull_vertices.max(axis=0)
        c = near_pts[((near_pts > lo) & (near_pts < hi)).all(axis=1)]
        if not len(c) or not inside(lb.hull_vertices, lb.hull_faces, c).any():
            continue
        if carve_lobe(lobes, k, pts, wood, radius):
            changed += 1
    return changed


_PLAIN: dict[int, tuple[weakref.ref, Tetrahedra]] = {}
"""The plain tetrahedralisation of each lobe, by the id of its ``members`` array, while that array lives
(kept lobes share it across refinements; not part of ``LobeState``, so it never travels with one)."""


def remember_plain(members: np.ndarray, tet: Tetrahedra) -> None:
    """Keep ``tet`` (``Tetrahedra`` of the points ``members`` indexes) for ``carve_lobe`` while ``members`` lives."""
    key = id(members)

    def forget(ref: weakref.ref, key: int = key) -> None:
        if _PLAIN.get(key, (None,))[0] is ref:
            del _PLAIN[key]

    _PLAIN[key] = (weakref.ref(members, forget), tet)


def _recall_plain(members: np.ndarray, points: np.ndarray) -> Tetrahedra | None:
    """The ``Tetrahedra`` remembered for ``members`` if it was built from ``points`` (its lobe's points)."""
    hit = _PLAIN.get(id(members))
    ok = hit is not None and hit[0]() is members and np.array_equal(hit[1].source, points)
    return hit[1] if ok else None


def carve_lobe(lobes: list[LobeState], k: int, pts: np.ndarray, blockers: np.ndarray, radius: float) -> bool:
    """Rebuild lobe ``k``'s hull with the ``blockers`` (B, 3) within one probe radius of its points kept
    out, at most at its plain probe radius (in place); False when the carved shape is not usable."""
    lb = lobes[k]
    members = pts[lb.members]
    lo, hi = members.min(axis=0) - radius, members.max(axis=0) + radius
    near = blockers[((blockers > lo) & (blockers < hi)).all(axis=1)]
    steps = lb.steps if lb.steps is not None else plain_steps(members, radius) if lb.alpha else RADIUS_STEPS
    shape = carved_hull(members, radius, near, steps, _recall_plain(lb.members, members))
    if shape is None:
        return False
    lobes[k] = replace(lb, hull_vertices=shape[0], hull_faces=shape[1], alpha=True)
    return True


def part_overlaps(lobes: list[LobeState], start: int, mains: BranchSet, pts: np.ndarray, radius: float,
                  step: float = 0.005) -> int:
    """For each lobe from ``start`` on whose centre lies inside another lobe, carve that lobe with the
    first one's points and the main branches as blockers (in place); returns how many hulls changed.

    k-means clusters never need it (no centre of the decomposed test trees lies in another lobe), but
    points a user selects for ``insert_lobe`` border the lobe they came from, and the two alpha shapes
    (probe radius about a lobe's size) overlap: neither branch could reach its centre. Carving fails
    when the blockers split the shape; then the lobe's centre moves to its own point nearest the old
    centre outside every other lobe (its branch ends there), when it has one.
    """
    wood = sample_polylines(mains.segments, step)
    changed = 0
    for j in range(start, len(lobes)):
        c = lobes[j].centre[None]
        lo, hi = boxes(lobes)
        for k in np.flatnonzero(((c > lo) & (c < hi)).all(axis=1)):
            if k == j or not inside(lobes[k].hull_vertices, lobes[k].hull_faces, c).any():
                continue
            changed += carve_lobe(lobes, int(k), pts, np.concatenate([pts[lobes[j].members], wood]), radius)
        if inside_foreign(lobes, j, c)[0]:
            own = pts[lobes[j].members]
            free = own[~inside_foreign(lobes, j, own)]
            if len(free):
                lobes[j] = replace(lobes[j], centre=free[np.argmin(np.linalg.norm(free - c, axis=1))])
    return changed


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
               hulls: tuple[LobeState | None, ...] = ()) -> tuple[list[LobeState], np.ndarray, int]:
    """Lobes over the point-index ``groups`` with hulls and routed, merged secondary branches.

    ``others`` are lobes kept from before (zone ids 0..len(others)-1; the new lobes follow them).
    ``hulls[i]``, when given, is a lobe over ``groups[i]`` whose hull the group keeps (a kept lobe whose
    branch is routed again); other groups get their plain hull.
    Returns every lobe (``others`` first, then the new ones; any of them may come back with the main
    branches carved out, see ``unwrap``, or carved round a new lobe whose centre it buried, see
    ``part_overlaps``, which may instead move that new lobe's centre onto one of its own points), the
    routing predecessors (N,) and the number of branches routed again.
    """
    lobes = list(others)
    for i, (g, c) in enumerate(zip(groups, centres)):
        old = hulls[i] if i < len(hulls) else None
        if old is not None:
            verts, faces, used_alpha, steps = old.hull_vertices, old.hull_faces, old.alpha, old.steps
        else:
            verts, faces, used_alpha, steps, tet = plain_hull(pts[g], o.alpha_radius)
            remember_plain(g, tet)
        lobes.append(LobeState(g, np.asarray(c, np.float64), verts, faces, used_alpha, np.zeros((0, 3)), -1, -1,
                               steps))
    part_overlaps(lobes, len(others), mains, pts, o.alpha_radius)
    centres = [lb.centre for lb in lobes[len(others):]]
    _, pred = shortest_paths(weighted(adjacency, np.where(zone >= 0, ZONE_COST, 1.0)), root)
    targets = [int(g[np.argmin(np.linalg.norm(pts[g] - c, axis=1))]) for g, c in zip(groups, centres)]
    refs = main_references(mains, o.resample, o.sc_bins)
    merged = merge_secondaries(branch_paths(targets, pred, pts, grid, o.step), mains, tau, o.resample, o.sc_bins,
                               refs)
    raw = [_finish(seg, c) for (seg, _, _), c in zip(merged, centres)]
    tree = cKDTree(pts)
    smooth = smooth_polylines(raw, vertex_limits(raw, tree))
    for j, (seg, (_, parent, pv)) in enumerate(zip(smooth, merged), start=len(others)):
        lobes[j] = replace(lobes[j], segment=seg, parent=parent, parent_vertex=pv)
    rerouted = 0
    box = boxes(lobes)
    for j in range(len(others), len(lobes)):
        lb = lobes[j]
        seg = clear_smooth(lobes, j, raw[j - len(others)], lb.segment, o.step / 2, box, tree)
        if seg is not None:
            lobes[j] = replace(lb, segment=seg)
            continue
        rerouted += 1
        cost = np.where((zone >= 0) & (zone != j), FOREIGN_COST, np.where(zone == j, ZONE_COST, 1.0))
        _, p2 = shortest_paths(weighted(adjacency, cost), root)
        path = branch_paths([targets[j - len(others)]], p2, pts, grid, o.step)
        seg, parent, pv = merge_secondaries(path, mains, tau, o.resample, o.sc_bins, refs)[0]
        seg = _finish(seg, lb.centre)
        smoothed = smooth_polylines([seg], vertex_limits([seg], tree))[0]
        seg = clear_smooth(lobes, j, seg, smoothed, o.step / 2, box, tree)
        if seg is None:
            fallback = straight_fallback(lobes, j, mains) or bent_fallback(lobes, j, mains, pts)
            if fallback is None:
                fallback, box = _unwrapped_fallback(lobes, j, mains, pts, o.alpha_radius, box)
            seg, parent, pv = fallback or (smoothed, parent, pv)
        lobes[j] = replace(lb, segment=seg, parent=parent, parent_vertex=pv)
    return lobes, pred, rerouted
