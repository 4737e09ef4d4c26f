"""Algorithm 1 of VRTree (branch merge) and the connection-point smoothing of Eq. (1).

Branches start as shortest paths from the root. We resample each at a fixed arc-length ``step`` and
centre it in the cloud (each vertex moved to the centroid of the points around it), so paths that run up
opposite sides of a thick trunk coincide. Merging a path P_i into the most similar kept branch P_opt
walks both from the root: leading vertices of P_i closer than the threshold to P_opt are merged; the
first one that is not is the connection point v_j, joined by a new edge to v_i, the vertex of P_opt
nearest the last merged vertex (the one before v_j), then moved by Eq. (1):
v_j' = (v_i l_i + v_{j+1} l_{j+1}) / (l_i + l_{j+1}).

"Most similar" is the lowest shape-context assignment cost (similarity.py) among the kept branches that
share the longest merged prefix with P_i (within one vertex): on a shortest-path tree every path
shares an exact prefix with some kept branch, and merging into a branch with a shorter shared prefix
would duplicate wood that is already there.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from arboretum_library.geometry import polyline_lengths
from arboretum_server.jitcache import njit

from .grid import BoxGrid
from .memo import ArrayMemo
from .similarity import arc_lengths, assignment_costs, resample_all, shape_contexts


def resample_step(points: np.ndarray, step: float) -> np.ndarray:
    """``points`` (N, 3) resampled at arc-length spacing ~``step`` (M >= 2 vertices, ends kept).

    A compiled loop (``_resample_kernel``) gives bit for bit what ``resample_step_reference`` does with
    numpy (the tests hold the two together): a refinement resamples 200-300 short polylines, and numpy's
    per-call overhead made that a tenth of its time (session 15)."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2 or not (step > 0):
        return resample_step_reference(points, step)
    out = _resample_kernel(pts, float(step))
    return out if len(out) else resample_step_reference(points, step)


def resample_step_reference(points: np.ndarray, step: float) -> np.ndarray:
    """``resample_step`` in numpy: arc lengths, ``np.linspace`` and ``np.interp`` per axis (the slow reference)."""
    s = polyline_lengths(points)
    n = max(2, int(np.ceil(s[-1] / step)) + 1)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, points[:, k]) for k in range(3)], axis=1)


@njit(cache=True)
def _resample_kernel(pts: np.ndarray, step: float) -> np.ndarray:  # pragma: no cover - numba
    """``resample_step_reference`` for (N >= 2, 3) float64 ``pts``: the same float operations in the same
    order (``np.linalg.norm`` of the differences, a running sum, ``np.linspace``'s i * (length / (n - 1))
    with the end set to the length, and ``np.interp``'s interval search, slopes and exact hits)."""
    m = pts.shape[0]
    s = arc_lengths(pts)
    length = s[m - 1]
    if not np.isfinite(length):
        return np.zeros((0, 3))  # the reference's nan handling is not copied
    n = max(2, int(np.ceil(length / step)) + 1)
    delta = length / (n - 1)
    out = np.zeros((n, 3))
    j = 0
    for i in range(n):
        x = length if i == n - 1 else (i * delta if delta != 0.0 else (i / (n - 1)) * length)
        while j + 1 < m and x >= s[j + 1]:  # x grows: the last j with s[j] <= x
            j += 1
        for k in range(3):
            if j == m - 1 or s[j] == x:
                out[i, k] = pts[j, k]
            else:
                slope = (pts[j + 1, k] - pts[j, k]) / (s[j + 1] - s[j])
                out[i, k] = slope * (x - s[j]) + pts[j, k]
                if np.isnan(out[i, k]):  # np.interp tries the other end, then a flat interval's value
                    out[i, k] = slope * (x - s[j + 1]) + pts[j + 1, k]
                    if np.isnan(out[i, k]) and pts[j, k] == pts[j + 1, k]:
                        out[i, k] = pts[j, k]
    return out


def sample_polylines(polylines: list[np.ndarray], step: float) -> np.ndarray:
    """Points (M, 3) every ~``step`` along each polyline (N_i, 3)."""
    return np.concatenate([resample_step(p, step) for p in polylines]) if polylines else np.zeros((0, 3))


def drop(path: np.ndarray) -> float:
    """How far ``path`` (L, 3) falls below the highest point it reached before (0 if it never turns down)."""
    z = path[:, 2]
    return float((np.maximum.accumulate(z) - z).max()) if len(z) else 0.0


def centre_paths(paths: list[np.ndarray], grid: BoxGrid) -> list[np.ndarray]:
    """Each vertex of each path moved to the centroid of the cloud around it in ``grid`` (root kept)."""
    if not paths:
        return []
    out = grid.centroids(np.concatenate(paths))
    pieces = np.split(out, np.cumsum([len(p) for p in paths])[:-1])
    for p, q in zip(paths, pieces):
        q[0] = p[0]
    return pieces


def merged_prefix(cands: list[np.ndarray], ref: np.ndarray, tau: float, tree: cKDTree | None = None) -> np.ndarray:
    """For each candidate polyline (each >= 1 vertex), the index of its first vertex at least ``tau`` from
    ``ref`` (its length when there is none; ``tree``: a KD-tree of ``ref``, when known)."""
    return merged_prefixes(cands, [tree if tree is not None else cKDTree(ref)], tau)[:, 0]


def merged_prefixes(cands: list[np.ndarray], trees: list[cKDTree], tau: float) -> np.ndarray:
    """(P, M) int: ``merged_prefix`` of the P candidate polylines (each >= 1 vertex) against each of M
    references given by their KD-trees (the candidates joined once, not once per reference)."""
    lens = np.array([len(c) for c in cands])
    q = np.concatenate(cands)
    starts = np.r_[0, np.cumsum(lens)[:-1]]
    local = np.arange(len(q)) - np.repeat(starts, lens)
    out = np.zeros((len(cands), len(trees)), np.int64)
    for m, tree in enumerate(trees):
        far = tree.query(q)[0] >= tau
        out[:, m] = np.minimum.reduceat(np.where(far, local, np.repeat(lens, lens)), starts)
    return out


def merged_prefixes_flat(cands: list[np.ndarray], refs: list[np.ndarray], tau: float) -> np.ndarray:
    """``merged_prefixes`` against the reference polylines ``refs`` themselves (no KD-trees): a compiled
    loop (``_prefix_kernel``) walks each candidate from its first vertex, takes its distance to each
    reference's nearest vertex by brute force and stops at the first one at least ``tau`` away, so it
    measures only the merged prefix and one vertex more. The same integers as ``merged_prefixes`` (the
    same squared distances, their least, its square root compared with ``tau``; the tests hold the two
    together): a refinement merges one path at a time against 6-8 main branches, 300 times, and each
    KD-tree query cost 0.1 ms (session 26). Each candidate and reference needs >= 1 vertex."""
    lens = np.array([len(c) for c in cands], np.int64)
    rlens = np.array([len(r) for r in refs], np.int64)
    out = np.zeros((len(cands), len(refs)), np.int64)
    if not len(cands):
        return out
    q = np.ascontiguousarray(np.concatenate(cands), dtype=np.float64)
    ref = np.ascontiguousarray(np.concatenate(refs), dtype=np.float64) if refs else np.zeros((0, 3))
    _prefix_kernel(q, np.r_[0, np.cumsum(lens)[:-1]], lens, ref, np.r_[0, np.cumsum(rlens)[:-1]].astype(np.int64),
                   rlens, float(tau), out)
    return out


@njit(cache=True)
def _prefix_kernel(q, starts, lens, ref, rstarts, rlens, tau, out):  # pragma: no cover - numba
    """``merged_prefixes_flat``'s loop: ``out[p, m]`` = the first vertex of candidate p (rows ``starts[p]`` ..
    of ``q``) whose least distance to reference m (rows ``rstarts[m]`` .. of ``ref``) is >= ``tau``, else
    its length. A squared distance is summed as cKDTree sums it for three coordinates, ((0 + dx^2) + dy^2)
    + dz^2, the least kept, and its square root compared (cKDTree's reported distance)."""
    for p in range(len(starts)):
        for m in range(len(rstarts)):
            k = lens[p]
            for v in range(lens[p]):
                i = starts[p] + v
                best = np.inf
                for r in range(rstarts[m], rstarts[m] + rlens[m]):
                    dx, dy, dz = q[i, 0] - ref[r, 0], q[i, 1] - ref[r, 1], q[i, 2] - ref[r, 2]
                    d = dx * dx + dy * dy + dz * dz
                    if d < best:
                        best = d
                if np.sqrt(best) >= tau:
                    k = v
                    break
            out[p, m] = k


WANDER = 1.3
"""Largest ratio of arc length to straight reach that counts toward a candidate's novelty."""


@dataclass
class BranchSet:
    """Branches built by Algorithm 1 (mutable while building; copied by the refinement operations)."""

    segments: list[np.ndarray] = field(default_factory=list)
    """Stored polylines (L, 3): from the connection point on the parent to the tip."""
    parents: list[int] = field(default_factory=list)
    parent_vertex: list[int] = field(default_factory=list)
    full: list[np.ndarray] = field(default_factory=list)
    """Full polylines from the root (L, 3), used for similarity and merging."""
    owner: list[np.ndarray] = field(default_factory=list)
    """(L, 2) int: (segment, vertex) owning each vertex of ``full``."""
    raw_full: list[np.ndarray] = field(default_factory=list)
    """After smoothing: the unsmoothed ``full`` paths (same vertex counts). Graph paths merge against
    these (both zig-zag through the same points); connections go to the smoothed vertices. Empty before."""

    def reference(self, b: int) -> np.ndarray:
        """The full path of branch ``b`` that candidate paths are compared with (unsmoothed if known)."""
        return self.raw_full[b] if self.raw_full else self.full[b]


def _length(v: np.ndarray) -> np.float64:
    """``np.linalg.norm`` of a 1-D float vector, the same value (it computes ``sqrt(v.dot(v))``) without its
    argument handling: a refinement takes some 1,600 such norms in ``attach``."""
    return np.sqrt(v.dot(v))


def eq1(v_i: np.ndarray, v_j: np.ndarray, v_next: np.ndarray) -> np.ndarray:
    """Eq. (1): the connection point v_j moved to (v_i l_i + v_{j+1} l_{j+1}) / (l_i + l_{j+1})."""
    l_i, l_n = _length(v_i - v_j), _length(v_next - v_j)
    if l_i + l_n <= 1e-12:
        return v_j
    return (v_i * l_i + v_next * l_n) / (l_i + l_n)


def choose_parent(ks: np.ndarray, hist: np.ndarray, ref_hists: np.ndarray) -> int:
    """Index of P_opt: among the kept branches whose merged prefixes ``ks`` (M,) are within one vertex of
    the longest, the one with the lowest shape-context assignment cost (``hist`` (n, k) against
    ``ref_hists`` (M, n, k))."""
    close = np.flatnonzero(ks >= ks.max() - 1)
    if len(close) == 1:
        return int(close[0])
    costs = assignment_costs(hist, ref_hists, close)
    return int(close[int(np.argmin(costs))])


def attach(path: np.ndarray, kept: BranchSet, opt: int, k: int, tree: cKDTree | None = None) -> tuple[np.ndarray, int, int]:
    """Merge ``path`` into ``kept.full[opt]`` after ``k`` merged vertices.

    Returns the new segment (first vertex = v_i on the parent), the parent segment and its vertex.
    """
    k = int(min(max(k, 1), len(path)))
    ref = kept.reference(opt)
    i_ref = nearest_vertex(ref, path[k - 1])
    if i_ref < 0:  # a tie (or no number): the KD-tree's choice, as before session 26
        i_ref = int((tree or cKDTree(ref)).query(path[k - 1])[1])
    v_i = kept.full[opt][i_ref]
    seg, pv = (int(x) for x in kept.owner[opt][i_ref])
    tail = path[k:]
    if len(tail) == 0:
        tail = path[-1:]
    tail = tail.copy()
    if len(tail) >= 2:
        tail[0] = eq1(v_i, tail[0], tail[1])
    if _length(tail[0] - v_i) < 1e-9:
        tail = tail[1:] if len(tail) > 1 else tail + 1e-6
    return np.concatenate([v_i[None], tail]), seg, pv


def nearest_vertex(ref: np.ndarray, q: np.ndarray) -> int:
    """Index of the vertex of ``ref`` (L, 3) nearest ``q`` (3,) when exactly one is nearest (then the one
    ``cKDTree(ref).query(q)`` gives: the same squared distances, ``_nearest_kernel``), else -1 (a tie, an
    empty or non-finite input: ask the tree). Session 26: 2 us against the tree's 25 us a query."""
    ref = np.ascontiguousarray(ref, dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    if ref.ndim != 2 or ref.shape[1] != 3 or q.shape != (3,):
        return -1
    return int(_nearest_kernel(ref, q))


@njit(cache=True)
def _nearest_kernel(ref, q):  # pragma: no cover - numba
    """``nearest_vertex``'s loop: squared distances summed as cKDTree sums three coordinates, ((0 + dx^2)
    + dy^2) + dz^2; the index of the least, -1 if another vertex ties it or none is a number."""
    best, arg, tie = np.inf, -1, False
    for r in range(ref.shape[0]):
        dx, dy, dz = q[0] - ref[r, 0], q[1] - ref[r, 1], q[2] - ref[r, 2]
        d = dx * dx + dy * dy + dz * dz
        if d < best:
            best, arg, tie = d, r, False
        elif d == best:
            tie = True
    return -1 if tie else arg


def add_branch(kept: BranchSet, segment: np.ndarray, parent: int, pv: int) -> None:
    """Append ``segment`` (attached at vertex ``pv`` of segment ``parent``, -1 for the root branch)."""
    b = len(kept.segments)
    own = np.stack([np.full(len(segment), b), np.arange(len(segment))], axis=1)
    if parent < 0:
        full, owner = segment, own
    else:
        anc = parent  # a segment's full path holds its own vertices and its ancestors'
        cut = int(np.flatnonzero((kept.owner[anc][:, 0] == parent) & (kept.owner[anc][:, 1] == pv))[0])
        full = np.vstack([kept.full[anc][: cut + 1], segment[1:]])
        owner = np.vstack([kept.owner[anc][: cut + 1], own[1:]])
    kept.segments.append(segment)
    kept.parents.append(parent)
    kept.parent_vertex.append(pv)
    kept.full.append(full)
    kept.owner.append(owner)


def select_mains(paths: list[np.ndarray], n_main: int, tau: float, step: float,
                 reach_weight: float = 0.5) -> list[int]:
    """Indices of ``n_main`` paths: the longest, then each time the one scoring highest beyond the kept ones.

    The score is reach ** w * spread ** (1 - w) with w = ``reach_weight``: by default the geometric mean
    of two readings of "new wood" (ours; measured in docs/decomposition-experiments.md):

    - *reach*: against each kept path, the arc length beyond the leading run of the path's vertices
      within ``tau`` of it (``merged_prefix``), capped at ``WANDER`` times the straight distance from
      there to the tip, so paths that wander through foliage are not rewarded; the least over the kept
      paths;
    - *spread*: the largest distance of any of the path's vertices from the kept paths.

    A path with less than two ``step`` of reach is never chosen, so fewer than ``n_main`` indices come
    back when no path has that much left.

    Reach alone rewards paths that climb beside a kept branch just outside the merge threshold (through
    foliage, or up the far side of a trunk the scan saw only in part) or hop between a conifer's crowded
    whorls; spread alone prefers short lateral branches to long upright ones, which is right for an
    excurrent crown (the pine: w = 0, ``options.REACH_WEIGHTS``).
    """
    lens = np.array([len(p) for p in paths])
    tips = np.array([p[-1] for p in paths])
    chosen = [int(np.argmax(lens))]
    verts, starts = np.concatenate(paths), np.r_[0, np.cumsum(lens)[:-1]]

    def reach(ref: int) -> np.ndarray:
        k = np.maximum(merged_prefix(paths, paths[ref], tau), 1)
        last = np.array([p[min(j, len(p)) - 1] for p, j in zip(paths, k)])
        straight = np.linalg.norm(tips - last, axis=1)
        return np.minimum((lens - k) * step, WANDER * straight)

    novelty = reach(chosen[0])
    gap = cKDTree(paths[chosen[0]]).query(verts)[0]
    while len(chosen) < n_main:
        # a path with less than two steps of new wood is no candidate, however far it spreads
        spread = np.maximum.reduceat(gap, starts)
        score = np.where(novelty >= 2 * step, novelty ** reach_weight * spread ** (1.0 - reach_weight), -1.0)
        score[chosen] = -1
        best = int(np.argmax(score))
        if score[best] < 0:
            break
        chosen.append(best)
        novelty = np.minimum(novelty, reach(best))
        gap = np.minimum(gap, cKDTree(paths[best]).query(verts)[0])
    return chosen


def _hists(polylines: list[np.ndarray], n: int, bins: tuple[int, int, int]) -> np.ndarray:
    return shape_contexts(resample_all(polylines, n), bins)


def merge_mains(paths: list[np.ndarray], order: list[int], tau: float, n: int,
                bins: tuple[int, int, int]) -> BranchSet:
    """Algorithm 1, step 1: main branches from ``paths[order]`` (the first is the longest)."""
    kept = BranchSet()
    add_branch(kept, paths[order[0]], -1, -1)
    hists = _hists([paths[i] for i in order], n, bins)
    for j, i in enumerate(order[1:], start=1):
        ks = np.array([merged_prefix([paths[i]], f, tau)[0] for f in kept.full])
        opt = choose_parent(ks, hists[j], hists[:j])
        seg, parent, pv = attach(paths[i], kept, opt, int(ks[opt]))
        add_branch(kept, seg, parent, pv)
    return kept


_REFERENCES = ArrayMemo()
"""``main_references``' shape contexts and KD-trees by the first reference path's array, while it lives,
with weak references to the other paths they were computed for: every refinement of a decomposition
routes against the same main branches (a BranchSet's arrays are replaced, never changed in place)."""


def main_references(mains: BranchSet, n: int, bins: tuple[int, int, int]) -> tuple[list, np.ndarray, list]:
    """What ``merge_secondaries`` compares every path with: the main branches' reference paths, their
    shape contexts and KD-trees; computed once per set of main branches (``_REFERENCES``): before session
    15 every ``make_lobes`` call of every refinement (one to three each) computed them again."""
    refs = [mains.reference(b) for b in range(len(mains.full))]
    if not refs:
        return refs, _hists(refs, n, bins), []
    key = (n, tuple(bins), len(refs))
    hit = _REFERENCES.get(refs[0])
    if hit is None or hit[0] != key or any(w() is not a for w, a in zip(hit[1], refs)):
        # the trees hold copies: a tree holding refs[0] itself would keep its own entry alive
        hit = _REFERENCES.put(refs[0], (key, [weakref.ref(a) for a in refs], _hists(refs, n, bins),
                                        [cKDTree(f.copy()) for f in refs]))
    return refs, hit[2], hit[3]


def merge_secondaries(paths: list[np.ndarray], mains: BranchSet, tau: float, n: int,
                      bins: tuple[int, int, int], references: tuple | None = None) -> list[tuple[np.ndarray, int, int]]:
    """Algorithm 1, step 2: (segment, parent main branch, parent vertex) for each secondary path.
    ``references``: ``main_references(mains, n, bins)``, when already computed."""
    if not paths:
        return []
    refs, hm, trees = references if references is not None else main_references(mains, n, bins)
    ks = merged_prefixes_flat(paths, refs, tau)  # (P, M)
    hp = _hists(paths, n, bins)
    out = []
    for p, path in enumerate(paths):
        opt = choose_parent(ks[p], hp[p], hm)
        out.append(attach(path, mains, opt, int(ks[p, opt]), trees[opt]))
    return out


def warm() -> None:
    """Run the compiled loops once: ``resample_step``'s, ``merged_prefixes_flat``'s, ``nearest_vertex``'s
    (see ``tetloops.warm``)."""
    resample_step(np.array([[0.0, 0, 0], [0, 0, 1]]), 0.25)
    merged_prefixes_flat([np.zeros((2, 3))], [np.ones((2, 3))], 0.5)
    nearest_vertex(np.eye(3), np.zeros(3))
