"""Dijkstra's algorithm with lazy guiding vectors (Xu and Mould 2015, section 3.1.2).

When a node is finalised (popped with its least cost) its guiding vector is fixed from its parent's
(``fields``), and only then are the weights of its out-edges set: ``w = d_E (1 - e_E . v)``, written as
``d_E - E . v`` with the edge vector E = d_E e_E. A small floor (1e-12 d_E) keeps weights positive.
Several source nodes start at cost 0 with their own vectors (later iterations use the tree so far).
The search stops as soon as every target is finalised.

This is a tight pure-Python loop over edge tuples (numba is not a dependency).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from .yao import YaoGraph

PI = math.pi
VERTICAL = 1e-9


@dataclass
class FlatGraph:
    """A Yao graph as Python lists for the search loop, built once per tree.

    ``edges[indptr[u]:indptr[u + 1]]`` are node u's out-edges as tuples (target, d_E, Ex, Ey, Ez);
    empty sectors are left out. Unpacking tuples in the loop is cheaper than indexing five lists.
    """

    indptr: list
    edges: list
    px: list
    py: list

    @classmethod
    def of(cls, g: YaoGraph) -> FlatGraph:
        n, s = g.neighbours.shape
        nbr = g.neighbours.ravel()
        keep = nbr != np.repeat(np.arange(n), s)
        v = g.vectors.reshape(-1, 3)[keep]
        indptr = np.concatenate([[0], np.cumsum(keep.reshape(n, s).sum(axis=1))])
        cols = (
            nbr[keep].tolist(),
            g.lengths.ravel()[keep].tolist(),
            v[:, 0].tolist(),
            v[:, 1].tolist(),
            v[:, 2].tolist(),
        )
        return cls(
            indptr.tolist(), list(zip(*cols)), g.points[:, 0].tolist(), g.points[:, 1].tolist()
        )


@dataclass
class Search:
    """Result of one search. Unreached nodes have parent -1, cost inf and done False."""

    parent: np.ndarray
    """(N,) int64: predecessor on the least-cost path; -1 for sources and unreached nodes."""
    hops: np.ndarray
    """(N,) int64: h, edges from the source set."""
    theta: np.ndarray
    """(N,) float64: guiding vector polar angle from +Z, radians."""
    phi: np.ndarray
    """(N,) float64: guiding vector azimuth, radians."""
    origin: np.ndarray
    """(N,) int64: the source node each path starts from."""
    cost: np.ndarray
    """(N,) float64: least cost from the source set."""
    done: np.ndarray
    """(N,) bool: finalised."""


def lazy_dijkstra(
    fg: FlatGraph,
    sources: np.ndarray,
    theta: np.ndarray,
    phi: np.ndarray,
    alpha_near: np.ndarray | None,
    alpha_far: np.ndarray | None,
    h0: float,
    targets: np.ndarray | None = None,
) -> Search:
    """Least-cost paths from ``sources`` with guiding vectors fixed when nodes are finalised.

    Args:
        fg: the graph.
        sources: (M,) source nodes; they start at cost 0 and keep their vectors.
        theta, phi: (N,) vectors: read for the sources; for the other nodes too when ``alpha_near``
            is None (a directly set field), else overwritten.
        alpha_near, alpha_far: (N,) rotation (radians) per node for h <= h0 and h > h0, or None.
        h0: switch-over hop count.
        targets: stop once all of these are finalised (None: search the whole graph).
    """
    n = len(fg.px)
    ip, edges, px, py = fg.indptr, fg.edges, fg.px, fg.py
    th, ph = theta.tolist(), phi.tolist()
    field = alpha_near is None
    a_near = [] if field else alpha_near.tolist()
    a_far = [] if field else alpha_far.tolist()
    cost = [math.inf] * n
    done = [False] * n
    par = [-1] * n
    tpar = [-1] * n
    hop = [0] * n
    org = list(range(n))
    want = set() if targets is None else {int(t) for t in targets}
    left = len(want) if targets is not None else -1
    heap = [(0.0, int(s)) for s in sources]
    heapq.heapify(heap)
    for _, s in heap:
        cost[s] = 0.0
    pop, push, sin, cos, atan2 = heapq.heappop, heapq.heappush, math.sin, math.cos, math.atan2
    while heap:
        c, u = pop(heap)
        if done[u]:
            continue
        done[u] = True
        pu = tpar[u]
        if pu >= 0:
            h = hop[pu] + 1
            hop[u], par[u], org[u] = h, pu, org[pu]
            if not field:
                tp = th[pu]
                t = tp + (a_near[u] if h <= h0 else a_far[u])
                th[u] = 0.0 if t < 0.0 else (PI if t > PI else t)
                ph[u] = atan2(py[u] - py[pu], px[u] - px[pu]) if tp < VERTICAL else ph[pu]
        if left >= 0 and u in want:
            left -= 1
            if left == 0:
                break
        st = sin(th[u])
        vx, vy, vz = st * cos(ph[u]), st * sin(ph[u]), cos(th[u])
        for e, d, x, y, z in edges[ip[u] : ip[u + 1]]:
            if done[e]:
                continue
            w = d - (x * vx + y * vy + z * vz)
            nc = c + (w if w > 1e-12 * d else 1e-12 * d)
            if nc < cost[e]:
                cost[e] = nc
                tpar[e] = u
                push(heap, (nc, e))
    return Search(
        np.array(par), np.array(hop), np.array(th), np.array(ph), np.array(org),
        np.where(np.array(done), np.array(cost), np.inf), np.array(done),
    )  # fmt: skip


# ---- fast path: the lazy result as the fixed point of static searches in scipy's C Dijkstra ----


@dataclass
class CsrGraph:
    """The Yao graph's real edges (self-loops of empty sectors dropped) in CSR layout, built once."""

    rows: np.ndarray
    cols: np.ndarray
    indptr: np.ndarray
    vec: np.ndarray
    length: np.ndarray
    n: int

    @classmethod
    def of(cls, g: YaoGraph) -> CsrGraph:
        n, s = g.neighbours.shape
        rows = np.repeat(np.arange(n), s)
        cols = g.neighbours.ravel().astype(np.int64)
        keep = cols != rows
        indptr = np.concatenate([[0], np.cumsum(keep.reshape(n, s).sum(axis=1))])
        return cls(
            rows[keep],
            cols[keep],
            indptr,
            g.vectors.reshape(-1, 3)[keep],
            g.lengths.ravel()[keep],
            n,
        )


def _levels(parent: np.ndarray, sources: np.ndarray) -> list[np.ndarray]:
    """Nodes by hop count from ``sources`` along ``parent`` links (level 0 = the sources)."""
    child = np.flatnonzero(parent >= 0)
    order = child[np.argsort(parent[child], kind="stable")]
    sp = parent[order]
    levels = [np.asarray(sources)]
    while True:
        lo = np.searchsorted(sp, levels[-1])
        cnt = np.searchsorted(sp, levels[-1], side="right") - lo
        total = int(cnt.sum())
        if total == 0:
            return levels
        start = np.repeat(lo - (np.cumsum(cnt) - cnt), cnt)
        levels.append(order[start + np.arange(total)])


def _propagate(
    points, parent, sources, theta, phi, near, far, h0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hops and guiding vectors of every reached node given the tree ``parent`` (the rule of fields)."""
    th, ph = theta.copy(), phi.copy()
    hops = np.zeros(len(parent), np.int64)
    for h, nodes in enumerate(_levels(parent, sources)[1:], start=1):
        p = parent[nodes]
        hops[nodes] = h
        if near is None:
            continue
        tp = th[p]
        t = tp + (near[nodes] if h <= h0 else far[nodes])
        th[nodes] = np.clip(t, 0.0, PI)
        edge = np.arctan2(points[nodes, 1] - points[p, 1], points[nodes, 0] - points[p, 0])
        ph[nodes] = np.where(tp < VERTICAL, edge, ph[p])
    return hops, th, ph


def lazy_dijkstra_fast(
    cg: CsrGraph, points: np.ndarray, sources: np.ndarray, theta: np.ndarray, phi: np.ndarray,
    alpha_near: np.ndarray | None, alpha_far: np.ndarray | None, h0: float, max_runs: int = 40,
) -> Search | None:  # fmt: skip
    """The same result as ``lazy_dijkstra`` (whole graph), or None when ``max_runs`` do not converge.

    Start with every non-source vector vertical; repeat: weights from the current vectors, one static
    multi-source search (scipy, C), vectors re-derived from the resulting tree by the rule. Once the
    tree no longer changes, every node's out-edge weights are those the lazy search would have set
    when finalising it, so the static search replays the lazy one: the fixed point is its result.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    sources = np.unique(sources)
    th, ph = theta.copy(), phi.copy()
    if alpha_near is not None:
        rest = np.ones(cg.n, bool)
        rest[sources] = False
        th[rest] = 0.0
    prev = None
    for _ in range(max_runs):
        st = np.sin(th)
        v = np.stack([st * np.cos(ph), st * np.sin(ph), np.cos(th)], axis=1)[cg.rows]
        w = cg.length - (cg.vec[:, 0] * v[:, 0] + cg.vec[:, 1] * v[:, 1] + cg.vec[:, 2] * v[:, 2])
        w = np.maximum(w, 1e-12 * cg.length)
        mat = csr_matrix((w, cg.cols, cg.indptr), shape=(cg.n, cg.n))
        cost, pred, origin = dijkstra(mat, indices=sources, min_only=True, return_predecessors=True)
        pred = np.where(pred < 0, -1, pred).astype(np.int64)
        hops, th, ph = _propagate(points, pred, sources, theta, phi, alpha_near, alpha_far, h0)
        if prev is not None and np.array_equal(pred, prev):
            done = np.isfinite(cost)
            origin = np.where(origin < 0, np.arange(cg.n), origin).astype(np.int64)
            return Search(pred, hops, th, ph, origin, cost, done)
        prev = pred
    return None
