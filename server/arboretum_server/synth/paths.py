"""Dijkstra's algorithm with lazy guiding vectors (Xu and Mould 2015, section 3.1.2).

When a node is finalised (popped with its least cost) its guiding vector is fixed from its parent's
(``fields``), and only then are the weights of its out-edges set: ``w = d_E (1 - e_E . v)``, written as
``d_E - E . v`` with the edge vector E = d_E e_E. A small floor (1e-12 d_E) keeps weights positive.
Several source nodes start at cost 0 with their own vectors (later iterations use the tree so far).
The search stops as soon as every target is finalised: Dijkstra finalises nodes in the same order
however long it runs, and a finalised node's parent and vector never change again, so the paths to
the targets are those of the full search.

Two implementations: ``lazy_search`` (the numba kernel ``kernels.lazy_search`` over a ``CsrGraph``),
which the tree generator uses, and ``lazy_dijkstra``, a plain heapq loop kept as the slow,
obviously-correct reference that the tests compare the kernel with (identical parents). Both break
cost ties by node index, so they finalise nodes in the same order.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from .yao import YaoGraph

PI = math.pi
VERTICAL = 1e-9
"""A guiding vector with theta below this is vertical (its azimuth is taken from the edge)."""


@dataclass
class FlatGraph:
    """A ``CsrGraph`` as Python lists for the reference search loop.

    ``edges[indptr[u]:indptr[u + 1]]`` are node u's out-edges as tuples (target, d_E, Ex, Ey, Ez);
    empty sectors are left out. Unpacking tuples in the loop is cheaper than indexing five lists.
    """

    indptr: list
    edges: list
    px: list
    py: list

    @classmethod
    def of(cls, cg: CsrGraph) -> FlatGraph:
        cols = (cg.cols.tolist(), *(cg.edge[:, i].tolist() for i in range(4)))
        return cls(cg.indptr.tolist(), list(zip(*cols)), cg.px.tolist(), cg.py.tolist())


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


# ---- the fast search: the same loop as a numba kernel over CSR arrays ----


@dataclass
class CsrGraph:
    """The Yao graph's real edges (self-loops of empty sectors dropped) in CSR layout, built once."""

    indptr: np.ndarray
    """(N + 1,) int64: node u's out-edges are ``indptr[u]:indptr[u + 1]``."""
    cols: np.ndarray
    """(E,) int64: edge targets."""
    edge: np.ndarray
    """(E, 4) float64, metres: edge length d_E and edge vector E (target - source) per edge."""
    px: np.ndarray
    """(N,) float64: node X (for the azimuth of an edge leaving a vertical vector)."""
    py: np.ndarray
    """(N,) float64: node Y."""

    @classmethod
    def of(cls, g: YaoGraph) -> CsrGraph:
        from .interrupt import interruptible
        from .kernels import csr_edges

        with interruptible():
            indptr, cols, edge = csr_edges(g.neighbours, g.vectors, g.lengths)
        px, py = (np.ascontiguousarray(g.points[:, i]) for i in range(2))
        return cls(indptr, cols, edge, px, py)


def lazy_search(
    cg: CsrGraph,
    sources: np.ndarray,
    theta: np.ndarray,
    phi: np.ndarray,
    alpha_near: np.ndarray | None,
    alpha_far: np.ndarray | None,
    h0: float,
    targets: np.ndarray | None = None,
) -> Search:
    """``lazy_dijkstra`` in compiled code: the same arguments (with ``cg`` for the graph) and result."""
    from .interrupt import interruptible
    from .kernels import lazy_search as kernel

    n = len(cg.px)
    field = alpha_near is None
    near = np.zeros(n) if alpha_near is None else np.asarray(alpha_near, np.float64)
    far = np.zeros(n) if alpha_far is None else np.asarray(alpha_far, np.float64)
    want = np.zeros(n, bool)
    left = -1
    if targets is not None:
        want[np.asarray(targets, np.int64)] = True
        left = int(want.sum())
    th, ph = np.array(theta, np.float64), np.array(phi, np.float64)
    with interruptible():
        par, hops, org, cost, done = kernel(
            cg.indptr, cg.cols, cg.edge, cg.px, cg.py, np.asarray(sources, np.int64),
            th, ph, near, far, float(h0), field, want, left,
        )  # fmt: skip
    return Search(par, hops, th, ph, org, cost, done)


def reference_search(
    cg: CsrGraph, sources: np.ndarray, theta: np.ndarray, phi: np.ndarray,
    alpha_near: np.ndarray | None, alpha_far: np.ndarray | None, h0: float,
    targets: np.ndarray | None = None,
) -> Search:  # fmt: skip
    """``lazy_dijkstra`` with ``lazy_search``'s signature: the reference, for tests and the bench."""
    return lazy_dijkstra(FlatGraph.of(cg), sources, theta, phi, alpha_near, alpha_far, h0, targets)
