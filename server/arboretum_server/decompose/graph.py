"""The kNN graph of VRTree section 3.4: K neighbours within a query radius, weighted by length, bridged.

An edge weighs its length once for each of its two points that lists the other among its K nearest
(``_edges`` sums both directions): a mutual neighbour pair weighs twice its length, a one-sided pair
once, where the paper's Euclidean weights would be once for both (measured and kept:
docs/decomposition-experiments.md). A K = 5 graph of a real tree falls apart into components
(``stats.components``: 2-50 on the bundled scans); we join them into one with bridges (``_bridges``: a
minimum spanning tree over components of the shortest candidate edge between each two) and report how
many we added. Shortest paths from the root use Dijkstra.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree
from scipy.spatial import cKDTree

from arboretum_library.signals import held
from arboretum_server.jitcache import njit

CANDIDATES = 16
"""Neighbours queried per point for bridging candidates (beyond the K graph neighbours)."""
SHORTCUT_REACH = 3.0
"""``gap_graph``: components whose boxes come within this many query radii of each other are joined."""
SHORTCUT_COST = 10.0
"""``gap_graph``: an edge across a scan gap costs this many times its length (wood is preferred)."""


@dataclass(frozen=True, eq=False)
class Graph:
    """A connected, symmetric kNN graph over a cloud, weighted by edge length (a mutual pair twice)."""

    adjacency: csr_matrix
    """(N, N) symmetric CSR, weights = edge lengths, doubled for a pair that are each other's neighbours
    (``_edges`` adds both directions); bridges count once."""
    components: int
    """Connected components before bridging."""
    bridges: int
    """Edges added to join them."""
    neighbours: np.ndarray
    """(N, k) int32: each point's nearest neighbours (itself excluded), for local features."""
    component: np.ndarray | None = None
    """(N,) int: each point's connected component before bridging (None: one component)."""
    tree: cKDTree | None = None
    """The KD-tree of the points the graph was built on (the pipeline's queries reuse it)."""


def _edges(a: np.ndarray, b: np.ndarray, w: np.ndarray, n: int) -> csr_matrix:
    m = coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(n, n)).tocsr()
    m.sum_duplicates()
    return m


PARALLEL_MIN = 50_000
"""``query`` splits a query of this many points or more over every core (each point's answer is its own, so
the same answer; below, starting the threads costs more than it saves)."""


def query(tree: cKDTree, q: np.ndarray, **kw) -> tuple[np.ndarray, np.ndarray]:
    """``tree.query(q, **kw)`` on every core for ``PARALLEL_MIN`` points or more: the whole-cloud queries of a
    ``--points 0`` run (a million points' 17 nearest: 3.2-4.7 s on one core, 1.6-2.7 s on this machine's
    two). ``OMP_NUM_THREADS``, when set, caps the threads as it does the BLAS's: a batch worker sets it to
    1, its parallelism coming from processes (docs/batch.md).

    A Ctrl-C waits for the query to end (``_interrupt_after``): scipy's worker threads would otherwise run on
    while the interpreter shut down under them, a segmentation fault in 4 of 26 interrupts of a
    738,510-point decomposition (session 17). The wait is short: the graph asks 65,536 points at a time, and
    the longest call, a million points' nearest lobe point, takes 0.5 s.
    """
    threads = query_threads() if len(q) >= PARALLEL_MIN else 1
    if threads == 1:
        return tree.query(q, **kw)
    with _interrupt_after():
        return tree.query(q, workers=threads, **kw)


@contextmanager
def _interrupt_after() -> Iterator[None]:
    """A SIGINT that arrives in the block is held and raised again when the block ends, to whatever
    handler was there (Python's: ``KeyboardInterrupt``)."""
    with held(signal.SIGINT) as got:
        yield
    if got:
        signal.raise_signal(signal.SIGINT)


def query_threads() -> int:
    """Threads for a whole-cloud query: ``OMP_NUM_THREADS`` when it is a whole number >= 1, else -1 (every core)."""
    value = os.environ.get("OMP_NUM_THREADS", "").strip()
    return int(value) if value.isdigit() and int(value) >= 1 else -1


QUERY_CHUNK = 1 << 16
"""``knn_graph`` asks the KD-tree for this many points' neighbours at a time, keeping the indices as int32:
the whole (N, K + 1) int64 answer of one query is never held (136 MB on a million points)."""


def _neighbours(tree: cKDTree, points: np.ndarray, kq: int) -> tuple[np.ndarray, np.ndarray]:
    """(distances (N, kq - 1) float64, indices (N, kq - 1) int32) of each point's ``kq`` nearest, the first
    column (the point itself) dropped; asked ``QUERY_CHUNK`` points at a time (each point's answer is its
    own, so the same as one query)."""
    n = len(points)
    index = np.int32 if n < 2**31 else np.int64  # indices wrap silently beyond int32
    dist, nb = np.zeros((n, kq - 1)), np.zeros((n, kq - 1), index)
    for s in range(0, n, QUERY_CHUNK):
        d, j = query(tree, points[s : s + QUERY_CHUNK], k=kq)
        dist[s : s + QUERY_CHUNK] = d.reshape(len(d), -1)[:, 1:]
        nb[s : s + QUERY_CHUNK] = j.reshape(len(j), -1)[:, 1:]
    return dist, nb


def knn_graph(points: np.ndarray, k: int, radius: float) -> Graph:
    """Graph of ``points`` (N, 3): each point to its ``k`` nearest within ``radius``, then bridged."""
    n = len(points)
    tree = cKDTree(points)
    kq = min(n, max(k, CANDIDATES) + 1)
    dist, nb = _neighbours(tree, points, kq)
    rows, col = np.nonzero(dist[:, :k] <= radius)
    adj = _edges(rows.astype(nb.dtype), nb[rows, col], np.maximum(dist[rows, col], 1e-12), n)
    del rows, col
    ncomp, lab = connected_components(adj, directed=False)
    if ncomp == 1:
        return Graph(adj, 1, 0, nb, tree=tree)
    a, b, w = _bridges(points, tree, lab, ncomp, dist, nb)
    adj = (adj + _edges(a, b, np.maximum(w, 1e-12), n)).tocsr()
    return Graph(adj, ncomp, len(a), nb, lab, tree)


def gap_graph(points: np.ndarray, g: Graph, radius: float) -> csr_matrix | None:
    """``g``'s adjacency (N, N) with every edge across a scan gap ``SHORTCUT_COST`` times its length:
    the bridges, and, between every two components (before bridging; past ``MAX_PAIRS_COMPONENTS`` or
    ``QUERY_BUDGET``, every two big ones: ``_near_pairs``) whose boxes lie within ``SHORTCUT_REACH`` x
    ``radius``, an edge from each point of the smaller one to its nearest point of the other within that
    reach. None for a graph of one component.

    The bridges of ``knn_graph`` are a minimum spanning tree over components of the shortest candidate
    edge between each two (``_bridges``), which can hang a trunk's upper part off a neighbouring limb
    where a scan gap cuts it from the fork below: the path to the top then climbs the limb and comes
    back down (scan 06). On this graph every gap costs the same per metre, so Dijkstra jumps the gap
    that saves the most path. ``pipeline.main_branches`` uses it only for paths that turn down and up
    again like that.
    """
    if g.component is None:
        return None
    lab = g.component
    coo = g.adjacency.tocoo()
    across = lab[coo.row] != lab[coo.col]
    w = np.where(across, SHORTCUT_COST * coo.data, coo.data)
    base = csr_matrix((w, (coo.row, coo.col)), shape=g.adjacency.shape)
    groups = np.split(np.argsort(lab, kind="stable"), np.cumsum(np.bincount(lab))[:-1])
    reach = SHORTCUT_REACH * radius
    trees: dict[int, cKDTree] = {}
    a, b, d = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [np.zeros(0)]
    for i, j in _near_pairs(points, groups, reach):
        small, big = (i, j) if len(groups[i]) <= len(groups[j]) else (j, i)
        if big not in trees:
            trees[big] = cKDTree(points[groups[big]])
        dist, k = trees[big].query(points[groups[small]], distance_upper_bound=reach)
        ok = np.isfinite(dist)
        a.append(groups[small][ok])
        b.append(groups[big][k[ok]])
        d.append(dist[ok])
    extra = _edges(np.concatenate(a), np.concatenate(b), SHORTCUT_COST * np.maximum(np.concatenate(d), 1e-12),
                   len(points))
    extra = (extra - extra.multiply(base != 0)).tocsr()  # an edge the graph has keeps its weight
    extra.eliminate_zeros()
    return (base + extra).tocsr()


MAX_PAIRS_COMPONENTS = 1000
"""``gap_graph`` pairs every two components up to this many; beyond, and when the pairs would query
more than ``QUERY_BUDGET`` points per point of the cloud, only the components holding ``BIG`` of the
points or more. Near-duplicate points leave each point its own component of copies (scan 06 given 6
times, 0.5 mm apart: 15,130 components, 27.8 M pairs, a MemoryError after 4 min)."""
QUERY_BUDGET = 50
BIG = 0.01


def _near_pairs(points: np.ndarray, groups: list[np.ndarray], reach: float) -> list[tuple[int, int]]:
    """Pairs (i, j) of components (point index arrays ``groups``) whose boxes come within ``reach``,
    among all of them or, past ``MAX_PAIRS_COMPONENTS`` or ``QUERY_BUDGET``, among the big ones."""
    sizes = np.array([len(ix) for ix in groups])
    every = np.arange(len(groups))
    big = np.flatnonzero(sizes >= BIG * len(points))
    for keep in ((every, big) if len(groups) <= MAX_PAIRS_COMPONENTS else (big,)):
        lo = np.array([points[groups[k]].min(axis=0) for k in keep]).reshape(-1, 3)
        hi = np.array([points[groups[k]].max(axis=0) for k in keep]).reshape(-1, 3)
        near = ((lo[:, None] - reach <= hi[None]) & (lo[None] - reach <= hi[:, None])).all(axis=2)
        i, j = np.nonzero(np.triu(near, 1))
        if keep is big or np.minimum(sizes[keep[i]], sizes[keep[j]]).sum() <= QUERY_BUDGET * len(points):
            return list(zip(keep[i].tolist(), keep[j].tolist()))
    return []


def _cross(lab: np.ndarray, dist: np.ndarray, nb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate edges (a, b, w) from the neighbour lists ``nb`` (N, k) (lengths ``dist``) whose two ends
    carry different labels ``lab``, in row-major order; one (N, k) bool mask, no (N k,) index copies."""
    i, j = np.nonzero(lab[nb] != lab[:, None])
    return i, nb[i, j].astype(np.int64), dist[i, j]


def _bridges(points, tree, lab, ncomp, dist, nb):
    """Shortest edges (a, b, w) that join ``ncomp`` components labelled ``lab`` into one."""
    a_all, b_all, w_all = [], [], []
    while True:
        # candidate inter-component edges from the neighbour lists
        ca, cb, cw = _cross(lab, dist, nb)
        ca, cb, cw = _isolated_edges(points, tree, lab, ncomp, ca, cb, cw)
        # minimum spanning tree over components using the shortest edge per component pair
        la, lb = lab[ca], lab[cb]
        order = np.lexsort((cw, np.minimum(la, lb), np.maximum(la, lb)))
        key = np.minimum(la, lb)[order] * ncomp + np.maximum(la, lb)[order]
        first = order[np.r_[True, key[1:] != key[:-1]]]
        comp = coo_matrix((cw[first] + 1e-12, (la[first], lb[first])), shape=(ncomp, ncomp))
        mst = minimum_spanning_tree(comp).tocoo()
        pick = {(min(i, j), max(i, j)) for i, j in zip(mst.row, mst.col)}
        sel = [e for e in first if (min(lab[ca[e]], lab[cb[e]]), max(lab[ca[e]], lab[cb[e]])) in pick]
        a_all.append(ca[sel])
        b_all.append(cb[sel])
        w_all.append(cw[sel])
        merged = coo_matrix((np.ones(len(sel)), (lab[ca[sel]], lab[cb[sel]])), shape=(ncomp, ncomp))
        n2, clab = connected_components(merged, directed=False)
        if n2 == 1:
            return np.concatenate(a_all), np.concatenate(b_all), np.concatenate(w_all)
        lab, ncomp = clab[lab], n2


def _isolated_edges(points, tree, lab, ncomp, ca, cb, cw):
    """Add, for each component with no candidate edge, its shortest edge to any other component."""
    has = np.zeros(ncomp, bool)
    has[lab[ca]] = True
    has[lab[cb]] = True
    extra_a, extra_b, extra_w = [ca], [cb], [cw]
    lonely = np.flatnonzero(~has)
    if len(lonely):
        order = np.argsort(lab, kind="stable")
        groups = np.split(order, np.cumsum(np.bincount(lab, minlength=ncomp))[:-1])
        for c in lonely:
            a, b, w = _nearest_pair(points, tree, groups[c], lab, c)
            extra_a.append(a)
            extra_b.append(b)
            extra_w.append(w)
    return np.concatenate(extra_a), np.concatenate(extra_b), np.concatenate(extra_w)


def _nearest_pair(points, tree, inside, lab, c):
    """The shortest edge (a, b, w) (arrays of one) from the points ``inside`` (component ``c`` of the
    labels ``lab``) to any other point.

    An upper bound first: the nearest outsider of the component's six extreme points (each point's
    len(inside) + 1 nearest neighbours hold one). The true pair's outsider then lies within that bound
    of the component's bounding ball, so the outsiders in the ball, each asked for its nearest insider
    (a KD-tree of the component), give the shortest edge without a tree of every other point (the
    shortest length exactly; where several edges tie, possibly another of them than
    ``nearest_pair_reference`` picks).
    """
    own = points[inside]
    if 2 * len(inside) > len(points):  # most of the cloud: ask each outsider for its nearest insider
        outside = np.flatnonzero(lab != c)
        d, k = query(cKDTree(own), points[outside])
        r = int(np.argmin(d))
        return inside[k[r : r + 1]], outside[r : r + 1], d[r : r + 1]
    ends = np.unique(np.r_[own.argmin(axis=0), own.argmax(axis=0)])
    d, j = tree.query(own[ends], k=min(len(points), len(inside) + 1))
    d = np.where(lab[j] != c, d, np.inf)
    first = np.unravel_index(int(np.argmin(d)), d.shape)
    bound, witness = float(d[first]), j[first]
    lo, hi = own.min(axis=0), own.max(axis=0)
    # the ball's radius padded by a few ulps of the coordinates: the KD-tree compares squared distances,
    # so an outsider exactly on the sphere (a straight run, whose extreme point is a box corner) may
    # fall just outside it; the bound's own outsider is always kept
    reach = float(np.linalg.norm(hi - lo)) / 2 + bound
    pad = 1e-9 * max(reach, float(np.abs(own).max()))
    near = np.asarray(tree.query_ball_point((lo + hi) / 2, reach + pad), np.int64)
    near = near[lab[near] != c]
    # only an outsider within the bound of the component's box can lie nearer than the bound: the others
    # are never the answer, so the KD-tree of the component is asked about fewer points
    gap = np.maximum(np.maximum(lo - points[near], points[near] - hi), 0.0)
    near = np.union1d(near[np.sqrt((gap * gap).sum(axis=1)) <= bound + pad], [witness])
    d, k = cKDTree(own).query(points[near])
    r = int(np.argmin(d))
    return inside[k[r : r + 1]], near[r : r + 1], d[r : r + 1]


def nearest_pair_reference(points, tree, inside, lab, c):
    """``_nearest_pair`` as it was before session 10: a KD-tree of every other point, built per
    component (the benchmark's baseline and the tests' reference)."""
    outside = np.flatnonzero(lab != c)
    small, big = (inside, outside) if len(inside) <= len(outside) else (outside, inside)
    d, j = cKDTree(points[big]).query(points[small])
    r = int(np.argmin(d))
    a, b = small[r : r + 1], big[j[r : r + 1]]
    return (a, b, d[r : r + 1]) if small is inside else (b, a, d[r : r + 1])


def shortest_paths(adj: csr_matrix, root: int) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic distance (N,) and predecessor (N,) int32 (-1 at the root) from node ``root``.

    ``adj`` must be symmetric (every graph here is: ``_edges`` adds both directions and ``weighted`` keeps
    them equal), so Dijkstra runs on it as a directed graph: the same paths, without the transposed copy
    an undirected run makes (35 % faster: 0.36 s instead of 0.56 s on 300,000 points).
    """
    dist, pred = dijkstra(adj, directed=True, indices=root, return_predecessors=True)
    pred = pred.astype(np.int32)
    pred[pred < 0] = -1
    return dist, pred


def _row_entries(adj: csr_matrix, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The CSR entries (K,) of the rows ``nodes`` (M,), and for each the position (K,) of its row in ``nodes``."""
    start, count = adj.indptr[nodes], np.diff(adj.indptr)[nodes]
    entry = np.repeat(start - np.r_[0, np.cumsum(count)[:-1]], count) + np.arange(int(count.sum()))
    return entry, np.repeat(np.arange(len(nodes)), count)


def path_cost(adj: csr_matrix, path: np.ndarray) -> float:
    """The length of ``path`` (M,) node indices in ``adj``, summed from the root end one edge at a time (as
    Dijkstra sums it, so never below the distance Dijkstra gives its last node). A missing edge counts 0."""
    a, b = np.asarray(path[:-1], np.int64), np.asarray(path[1:], np.int64)
    entry, at = _row_entries(adj, a)
    on = adj.indices[entry] == b[at]
    w = np.bincount(at[on], weights=adj.data[entry[on]], minlength=len(a))
    return float(np.cumsum(np.r_[0.0, w])[-1])


def path_is_unique(adj: csr_matrix, dist: np.ndarray, path: np.ndarray) -> bool:
    """Whether every node of ``path`` (M,) but the first has exactly one neighbour ``u`` whose distance plus
    edge gives its own (``dist[u] + w == dist[v]`` in float64, as Dijkstra adds them; ``adj`` symmetric):
    then no order of settling tied nodes can give it another predecessor, so the path is the one every
    run of Dijkstra finds."""
    v = np.asarray(path[1:], np.int64)
    entry, at = _row_entries(adj, v)
    hit = dist[adj.indices[entry]] + adj.data[entry] == dist[v[at]]
    return bool((np.bincount(at, weights=hit, minlength=len(v)) == 1).all())


def shortest_path_to(adj: csr_matrix, root: int, target: int, known: np.ndarray) -> np.ndarray:
    """Predecessors (N,) int32 from ``root`` whose path to ``target`` is ``tied_path``'s (and only that path
    is promised), given ``known``, any path root -> target.

    Dijkstra stops at the known path's length (scipy's ``limit``: nodes farther are never queued), which
    bounds the target's distance. Nodes within it get the same distances as in a full run, so the same
    tie-broken path; where Dijkstra's own predecessors along it are the only ones (``path_is_unique``: every
    synthetic run) it is that path, read without the walk. The reroutes of the secondary branches settle
    7-99 % of the points (median 57 %, the leaf-on pine): their lobes lie far out. Only when the bounded
    run misses the target (never seen) does a full run decide.
    """
    for limit in (path_cost(adj, known), np.inf):
        dist, pred = dijkstra(adj, directed=True, indices=root, return_predecessors=True, limit=limit)
        pred = pred.astype(np.int32)
        pred[pred < 0] = -1
        if not np.isfinite(dist[target]):
            continue
        path = path_to(pred, target)
        if path_is_unique(adj, dist, path) or (path := tied_path(adj, dist, root, target)) is not None:
            pred[path[1:]] = path[:-1]
            return pred
    raise ValueError(f"node {target} is not reachable from node {root}")


def path_after_cut(adj: csr_matrix, rows: np.ndarray, base: np.ndarray, cut: np.ndarray, root: int,
                   target: int) -> np.ndarray:
    """Node indices (M,) root -> ``target`` on ``adj``: the path ``shortest_path_to`` promises, node for node,
    given ``base``, Dijkstra's distances (N,) from ``root`` on the same graph with the edges ``cut`` (entry
    indices into ``adj.data``, both directions; ``rows``: each entry's row) no cheaper, and every other
    edge the same. Session 24: the reroutes of one ``make_lobes`` call differ only in their own lobe's zone
    edges, so one full run serves them all, each repaired where its cheaper edges lower a distance
    (``_repaired``) instead of a bounded run that settled 9,000-10,000 of the leaf-on pine's 12,000 points
    each (20 reroutes a split into 20).

    The same distances, bit for bit: ``_repaired`` ends at a fixed point of ``dist[v] = min(dist[u] + w)``
    (float64, as Dijkstra adds) no lower than any path's sum (each value is a path's sum, or ``base``'s, which
    only dearer edges gave), and with weights >= 0 and rounding monotone that fixed point is Dijkstra's.
    The same path: where each node's neighbour giving its distance is the only one (``path_is_unique``) it is
    the path any Dijkstra's predecessors give; else ``tied_path``'s. Never-seen cases (no tied step holds)
    go to ``shortest_path_to``."""
    a = adj.tocsr()
    data = np.ascontiguousarray(a.data, np.float64)
    dist = _repaired_to(a.indptr, a.indices, data, np.array(base, np.float64), rows, cut, int(target))
    path, unique = _unique_walk(a.indptr, a.indices, data, dist, int(root), int(target))
    if unique == 1:
        return path
    tied = tied_path(a, dist, root, target) if unique == 0 and np.isfinite(dist[target]) else None
    if tied is not None:
        return tied
    return path_to(shortest_path_to(a, root, target, np.array([root, target])), int(target))


def _repaired(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, dist: np.ndarray, rows: np.ndarray,
              cut: np.ndarray) -> np.ndarray:
    """``dist`` (N,) lowered in place to the fixed point of Dijkstra's relaxation over the CSR graph: the ``cut``
    entries relaxed first, then every lowered node relaxes its edges, nearest first (a heap of (distance,
    node), stale entries skipped; a node lowered again is queued again). ``_repaired_to`` run to the end."""
    return _repaired_to(indptr, indices, data, dist, rows, cut, -1)


@njit(cache=True)
def _repaired_to(indptr, indices, data, dist, rows, cut, target):  # pragma: no cover - numba
    """``_repaired``, stopped once the heap's nearest entry lies beyond ``dist[target]`` (never for ``target``
    -1). Session 26: every later entry, and so every later lowered value, is at least that entry's distance,
    so each node at or below ``dist[target]`` already holds its fixed-point value and every node above it
    stays above it: the walk back from ``target`` (``_unique_walk``, ``tied_path``: neighbours ``u`` with
    ``dist[u] + w == dist[v] <= dist[target]``, ``w >= 0``) sees the same ties as after the full repair.
    The nodes beyond keep values no lower than their fixed point's (read by nothing else)."""
    hd = np.zeros(indices.shape[0] + cut.shape[0] + 1)  # a node is settled once: at most one push per entry
    hn = np.zeros(indices.shape[0] + cut.shape[0] + 1, np.int64)
    size = 0
    for e in cut:
        nd = dist[rows[e]] + data[e]
        if nd < dist[indices[e]]:
            dist[indices[e]] = nd
            size = _push(hd, hn, size, nd, indices[e])
    while size > 0:
        d, v = hd[0], hn[0]
        if target >= 0 and d > dist[target]:
            break
        size = _pop(hd, hn, size)
        if d > dist[v]:
            continue  # stale: lowered again since
        for e in range(indptr[v], indptr[v + 1]):
            nd = d + data[e]
            if nd < dist[indices[e]]:
                dist[indices[e]] = nd
                size = _push(hd, hn, size, nd, indices[e])
    return dist


@njit(cache=True)
def _push(hd, hn, size, d, v):  # pragma: no cover - numba
    """(d, v) added to the binary min-heap ``hd``/``hn`` of ``size`` entries; the new size."""
    i = size
    while i > 0:
        p = (i - 1) // 2
        if hd[p] <= d:
            break
        hd[i], hn[i] = hd[p], hn[p]
        i = p
    hd[i], hn[i] = d, v
    return size + 1


@njit(cache=True)
def _pop(hd, hn, size):  # pragma: no cover - numba
    """The top of the binary min-heap ``hd``/``hn`` of ``size`` (>= 1) entries removed; the new size."""
    size -= 1
    if size == 0:
        return 0
    d, v = hd[size], hn[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and hd[c + 1] < hd[c]:
            c += 1
        if not hd[c] < d:
            break
        hd[i], hn[i] = hd[c], hn[c]
        i = c
    hd[i], hn[i] = d, v
    return size


@njit(cache=True)
def _unique_walk(indptr, indices, data, dist, root, target):  # pragma: no cover - numba
    """(path (M,) int64 root -> ``target``, 1) stepping back each time to the only neighbour ``u`` with
    ``dist[u] + w == dist[v]`` (``path_is_unique``'s test, over the node's CSR row); (empty, 0) when a node has
    several, (empty, -1) when one has none or the walk runs longer than the graph."""
    out = [target]
    v = target
    while v != root:
        found, count = -1, 0
        for e in range(indptr[v], indptr[v + 1]):
            if dist[indices[e]] + data[e] == dist[v]:
                count += 1
                found = indices[e]
        if count != 1:
            return np.zeros(0, np.int64), 0 if count > 1 else -1
        v = found
        out.append(v)
        if len(out) > dist.shape[0]:
            return np.zeros(0, np.int64), -1
    path = np.zeros(len(out), np.int64)
    for i in range(len(out)):
        path[i] = out[len(out) - 1 - i]
    return path, 1


def tied_path(adj: csr_matrix, dist: np.ndarray, root: int, target: int) -> np.ndarray | None:
    """Node indices (M,) root -> ``target`` stepping back, at each node ``v``, to the lowest-numbered neighbour
    ``u`` with ``dist[u] + w == dist[v]`` (as Dijkstra adds them) and ``dist[u] < dist[v]``: one shortest path
    whatever order Dijkstra settled tied nodes in, so a bounded run and a full run give the same. Real scans
    lie on a 1 mm grid and tie often (10 of the four scans' 80 reroutes at 12,000 points, all 19 of scan
    10 at full resolution); before session 17 each such reroute paid a second, full run. None when a step
    finds no such neighbour (``dist`` not from ``adj``)."""
    indptr, indices, data = adj.indptr, adj.indices, adj.data
    out, v = [int(target)], int(target)
    while v != root:
        s, e = indptr[v], indptr[v + 1]
        nb = indices[s:e]
        d = dist[nb]
        tie = nb[(d + data[s:e] == dist[v]) & (d < dist[v])]
        if len(tie) == 0:
            return None
        v = int(tie.min())
        out.append(v)
    return np.asarray(out[::-1], dtype=np.int64)


def path_to(pred: np.ndarray | list[int], node: int) -> np.ndarray:
    """Node indices (M,) from the root to ``node`` along the predecessor tree ``pred`` (an array, or the
    same as a list when many paths are read from one tree: the array is read node by node, never copied
    whole, which on a million points costs 50 ms per path)."""
    out = [node]
    while (p := int(pred[out[-1]])) >= 0:
        out.append(p)
    return np.asarray(out[::-1], dtype=np.int64)


def paths_to(pred: np.ndarray, nodes: list[int]) -> list[np.ndarray]:
    """``[path_to(pred, n) for n in nodes]``, the same int64 arrays, walked in one compiled call (``_paths_kernel``;
    session 29: a split into 100 pieces read its 100 paths node by node in Python, about 8 ms). ``pred`` is read in
    place (no list copy of a million entries). A ``pred`` that is not a 1-D integer array, a node outside it or a
    walk that leaves it or runs longer than it has entries (a cycle) goes to ``path_to`` (which raises or loops
    as it always did)."""
    arr = np.asarray(pred)
    idx = np.asarray(nodes, dtype=np.int64).reshape(-1)
    if (arr.ndim != 1 or arr.dtype.kind not in "iu" or len(idx) != len(nodes)
            or (len(idx) and (idx.min() < 0 or idx.max() >= len(arr)))):
        return [path_to(pred, n) for n in nodes]
    flat, first = _paths_kernel(arr, idx)
    if first[0] < 0:  # a walk left ``pred`` or did not end
        return [path_to(pred, n) for n in nodes]
    return [flat[first[i]:first[i + 1]] for i in range(len(idx))]


@njit(cache=True)
def _paths_kernel(pred, nodes):  # pragma: no cover - numba
    """(every path root -> node, joined; (K + 1,) offsets) for ``paths_to``, each as ``path_to`` walks it
    (predecessors up to the first negative one, then reversed); offsets[0] = -1 when a predecessor lies outside
    ``pred`` or a walk takes more steps than ``pred`` has entries."""
    n = pred.shape[0]
    first = np.zeros(nodes.shape[0] + 1, np.int64)
    for i in range(nodes.shape[0]):
        v, m = nodes[i], 1
        while pred[v] >= 0:
            v = pred[v]
            m += 1
            if v >= n or m > n:
                first[0] = -1
                return np.zeros(0, np.int64), first
        first[i + 1] = first[i] + m
    flat = np.zeros(first[nodes.shape[0]], np.int64)
    for i in range(nodes.shape[0]):
        v, at = nodes[i], first[i + 1] - 1
        flat[at] = v
        while pred[v] >= 0:
            v = pred[v]
            at -= 1
            flat[at] = v
    return flat, first


def weighted(adj: csr_matrix, node_weight: np.ndarray) -> csr_matrix:
    """A copy of ``adj`` whose edge weights are scaled by the larger node weight of their two ends."""
    adj = adj.tocsr()
    rows = np.repeat(np.arange(adj.shape[0]), np.diff(adj.indptr))
    w = adj.data * np.maximum(node_weight[rows], node_weight[adj.indices])
    return csr_matrix((w, adj.indices, adj.indptr), shape=adj.shape)


def warm() -> None:
    """Run every compiled loop here once on a two-node graph, with the dtypes the refinement passes (scipy's
    int32 CSR arrays, int64 entry lists; see ``tetloops.warm``), the heap's loops called once themselves."""
    adj = csr_matrix((np.array([1.0, 1.0]), (np.array([0, 1]), np.array([1, 0]))), shape=(2, 2))
    rows = np.repeat(np.arange(2), np.diff(adj.indptr))
    path_after_cut(adj, rows, np.array([0.0, 2.0]), np.flatnonzero(rows == 0), 0, 1)
    paths_to(np.array([-1, 0], np.int32), [1])
    hd, hn = np.zeros(2), np.zeros(2, np.int64)
    _pop(hd, hn, _push(hd, hn, 0, 1.0, adj.indices[0]))
