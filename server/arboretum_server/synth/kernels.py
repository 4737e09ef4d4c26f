"""numba kernels of the guiding-vector model: lazy search, k nearest, Yao edges, dart throwing.

Each kernel is the fast twin of a plain implementation that stays as the reference and that the tests
compare it with for equality: ``lazy_search`` of ``paths.lazy_dijkstra`` (the same floating-point
operations in the same order, the same tie-breaking), ``knn`` of ``cKDTree.query``, ``yao_select`` of
``yao.sector_of`` plus "nearest per sector", ``throw_darts`` of ``poisson.first_independent_set``
(``csr_edges`` only reshapes). Compiled on first use and cached to ``__pycache__`` (``cache=True``):
only the first process after a change of this file pays the compile time (15-25 s for all).
"""

from __future__ import annotations

import math

import numpy as np

from arboretum_server.jitcache import njit

PI = math.pi
VERTICAL = 1e-9
"""``paths.VERTICAL``, repeated here: numba's cache would not see a change in another module."""


@njit(cache=True)
def _up(hc, hn, pos, i):
    """Sift heap entry ``i`` up. The heap holds each open node once (``pos`` (N,): its slot, -1 if
    none), keyed by (cost ``hc``, node ``hn``): the order of heapq on (cost, node) tuples."""
    c, u = hc[i], hn[i]
    while i > 0:
        p = (i - 1) >> 1
        if hc[p] < c or (hc[p] == c and hn[p] < u):
            break
        hc[i], hn[i] = hc[p], hn[p]
        pos[hn[i]] = i
        i = p
    hc[i], hn[i] = c, u
    pos[u] = i


@njit(cache=True)
def _down(hc, hn, pos, size):
    """Sift the root entry down a heap of ``size`` entries."""
    c, u = hc[0], hn[0]
    i = 0
    while True:
        a = 2 * i + 1
        if a >= size:
            break
        b = a + 1
        if b < size and (hc[b] < hc[a] or (hc[b] == hc[a] and hn[b] < hn[a])):
            a = b
        if c < hc[a] or (c == hc[a] and u < hn[a]):
            break
        hc[i], hn[i] = hc[a], hn[a]
        pos[hn[i]] = i
        i = a
    hc[i], hn[i] = c, u
    pos[u] = i


@njit(cache=True)
def _relax(hc, hn, pos, size, e, nc):
    """Open node ``e`` at cost ``nc``, or lower its key; returns the new heap size."""
    if pos[e] < 0:
        hc[size], hn[size] = nc, e
        _up(hc, hn, pos, size)
        return size + 1
    hc[pos[e]] = nc
    _up(hc, hn, pos, pos[e])
    return size


@njit(cache=True)
def lazy_search(indptr, indices, edge, px, py, sources, th, ph, near, far, h0, field, want, left):
    """Dijkstra with lazy guiding vectors over a CSR graph; ``th``, ``ph`` (N,) are updated in place.

    indptr (N+1,), indices (E,) int64, edge (E, 4) float64 rows (d_E, E_x, E_y, E_z): the out-edges;
    px, py (N,): node X and Y; sources (M,) int64; near, far (N,): rotation for h <= h0 and h > h0
    (unused when ``field``); want (N,) bool: the targets, ``left`` of them (-1: search everything).
    An indexed binary heap with decrease-key: nodes finalise in the reference's (cost, node) order.
    Returns parent, hops, origin, cost (inf where not finalised), done.
    """
    n = len(px)
    cost = np.full(n, np.inf)
    done = np.zeros(n, np.bool_)
    par = np.full(n, -1, np.int64)
    tpar = np.full(n, -1, np.int64)
    hop = np.zeros(n, np.int64)
    org = np.arange(n)
    pos = np.full(n, -1, np.int64)
    hc = np.zeros(n)
    hn = np.zeros(n, np.int64)
    size = 0
    for s in sources:
        if cost[s] != 0.0:
            cost[s] = 0.0
            size = _relax(hc, hn, pos, size, s, 0.0)
    while size > 0:
        c, u = hc[0], hn[0]
        size -= 1
        if size > 0:
            hc[0], hn[0] = hc[size], hn[size]
            _down(hc, hn, pos, size)
        done[u] = True
        pu = tpar[u]
        if pu >= 0:  # fix u's parent, hops, origin and (unless a field) its guiding vector;
            h = hop[pu] + 1  # inline: as a separate function this loop ran 30% slower
            hop[u], par[u], org[u] = h, pu, org[pu]
            if not field:
                tp = th[pu]
                t = tp + (near[u] if h <= h0 else far[u])
                th[u] = 0.0 if t < 0.0 else (PI if t > PI else t)
                ph[u] = math.atan2(py[u] - py[pu], px[u] - px[pu]) if tp < VERTICAL else ph[pu]
        if left >= 0 and want[u]:
            left -= 1
            if left == 0:
                break
        st = math.sin(th[u])
        vx, vy, vz = st * math.cos(ph[u]), st * math.sin(ph[u]), math.cos(th[u])
        for j in range(indptr[u], indptr[u + 1]):
            e = indices[j]
            if done[e]:
                continue
            d = edge[j, 0]
            w = d - (edge[j, 1] * vx + edge[j, 2] * vy + edge[j, 3] * vz)
            nc = c + (w if w > 1e-12 * d else 1e-12 * d)
            if nc < cost[e]:
                cost[e] = nc
                tpar[e] = u
                size = _relax(hc, hn, pos, size, e, nc)
    cost = np.where(done, cost, np.inf)
    return par, hop, org, cost, done


@njit(cache=True)
def csr_edges(neighbours, vectors, lengths):
    """The Yao graph's real edges (self-loops of empty sectors dropped): indptr (N + 1,), cols (E,)
    int64 and edge (E, 4) rows (d_E, E_x, E_y, E_z), in sector order per node."""
    n, s = neighbours.shape
    indptr = np.zeros(n + 1, np.int64)
    for u in range(n):
        indptr[u + 1] = indptr[u]
        for j in range(s):
            indptr[u + 1] += neighbours[u, j] != u
    cols = np.zeros(indptr[n], np.int64)
    edge = np.zeros((indptr[n], 4))
    e = 0
    for u in range(n):
        for j in range(s):
            if neighbours[u, j] != u:
                cols[e] = neighbours[u, j]
                edge[e, 0] = lengths[u, j]
                edge[e, 1:] = vectors[u, j]
                e += 1
    return indptr, cols, edge


@njit(cache=True)
def _sector(x, y, z, sectors, lookup):
    """``yao.sector_of`` for one direction, the same comparisons in the same order."""
    if sectors == 8:
        return (1 if x > 0 else 0) + (2 if y > 0 else 0) + (4 if z > 0 else 0)
    a0, a1, a2 = abs(x), abs(y), abs(z)
    r0 = (1 if a1 > a0 else 0) + (1 if a2 > a0 else 0)
    r1 = (1 if a0 >= a1 else 0) + (1 if a2 > a1 else 0)
    r2 = (1 if a0 >= a2 else 0) + (1 if a1 >= a2 else 0)
    total = a0 + a1 + a2
    big = max(max(a0, a1), a2)
    mid = total - big - min(min(a0, a1), a2)
    c1 = -np.inf if sectors == 14 else (big + mid) / math.sqrt(2.0)
    c2 = total / math.sqrt(3.0)
    m = 1
    best = big
    if c1 > best:
        m, best = 2, c1
    if c2 > best:
        m = 3
    d0 = 0 if r0 >= m else (-1 if x < 0 else 1)
    d1 = 0 if r1 >= m else (-1 if y < 0 else 1)
    d2 = 0 if r2 >= m else (-1 if z < 0 else 1)
    return lookup[(d0 + 1) * 9 + (d1 + 1) * 3 + (d2 + 1)]


@njit(cache=True)
def yao_select(points, nb, sectors, lookup):
    """Per node and sector the first of ``nb`` (N, k), sorted by distance, in it: the Yao edges.

    Returns neighbours (N, S) int32 (the node itself where no neighbour falls in the sector), edge
    vectors (N, S, 3) and lengths (N, S) (zero there); ``lookup`` (27,) as ``yao._LOOKUP``.
    """
    n, k = nb.shape
    out = np.zeros((n, sectors), np.int32)
    vec = np.zeros((n, sectors, 3))
    length = np.zeros((n, sectors))
    for i in range(n):
        for s in range(sectors):
            out[i, s] = i
        for j in range(k):
            q = nb[i, j]
            x = points[q, 0] - points[i, 0]
            y = points[q, 1] - points[i, 1]
            z = points[q, 2] - points[i, 2]
            s = _sector(x, y, z, sectors, lookup)
            if out[i, s] == i:
                out[i, s] = q
                vec[i, s, 0], vec[i, s, 1], vec[i, s, 2] = x, y, z
                length[i, s] = math.sqrt(x * x + y * y + z * z)
    return out, vec, length


@njit(cache=True)
def _cells(points, size):
    """Grid of cubes of edge ``size`` over ``points``: per-point cell coordinates (N, 3), the grid
    dims (3,), its corner (3,), and the points sorted by cell (``start`` (C + 1,), ``items`` (N,))."""
    n = len(points)
    lo = np.zeros(3)
    dims = np.ones(3, np.int64)
    for a in range(3):
        lo[a] = points[:, a].min()
    cell = np.zeros((n, 3), np.int64)
    for i in range(n):
        for a in range(3):
            cell[i, a] = int((points[i, a] - lo[a]) / size)
            dims[a] = max(dims[a], cell[i, a] + 1)
    flat = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    start = np.zeros(dims[0] * dims[1] * dims[2] + 1, np.int64)
    for i in range(n):
        start[flat[i] + 1] += 1
    start = np.cumsum(start)
    items = np.argsort(flat, kind="mergesort")
    return cell, dims, lo, start, items


@njit(cache=True)
def _insert(bd, bi, cnt, d2, j):
    """Insert (d2, j) into the ascending best list ``bd``, ``bi`` of ``cnt`` entries (capacity k)."""
    k = len(bd)
    if cnt == k and d2 >= bd[k - 1]:
        return cnt
    p = cnt if cnt < k else k - 1
    while p > 0 and bd[p - 1] > d2:
        bd[p], bi[p] = bd[p - 1], bi[p - 1]
        p -= 1
    bd[p], bi[p] = d2, j
    return min(cnt + 1, k)


@njit(cache=True)
def _box_d2(p, lo, size, x, y, z):
    """Squared distance from ``p`` (3,) to grid cell (x, y, z)."""
    return (
        _gap2(p[0] - (lo[0] + x * size), size)
        + _gap2(p[1] - (lo[1] + y * size), size)
        + _gap2(p[2] - (lo[2] + z * size), size)
    )


@njit(cache=True)
def _gap2(f, size):
    """Squared distance from offset ``f`` to the interval [0, size]."""
    g = -f if f < 0.0 else (f - size if f > size else 0.0)
    return g * g


@njit(cache=True)
def knn(points, k, size):
    """(N, k) int64: each point's ``k`` nearest other points, nearest first (as cKDTree.query).

    Points are visited in grid-cell order (edge ``size``) over a cell-sorted copy; rings of cells are
    searched outwards, skipping cells farther than the current k-th distance, until the k-th distance
    is within the radius the searched block is known to cover.
    """
    n = len(points)
    cell, dims, lo, start, items = _cells(points, size)
    sp = points[items]
    out = np.zeros((n, k), np.int64)
    bd = np.zeros(k)
    bi = np.zeros(k, np.int64)
    reach = max(dims[0], max(dims[1], dims[2]))
    for q in range(n):
        i = items[q]
        c0, c1, c2 = cell[i, 0], cell[i, 1], cell[i, 2]
        p = sp[q]
        margin = np.inf
        for a in range(3):
            f = p[a] - (lo[a] + cell[i, a] * size)
            margin = min(margin, min(f, size - f))
        cnt = 0
        for ring in range(reach + 1):
            for x in range(max(c0 - ring, 0), min(c0 + ring + 1, dims[0])):
                for y in range(max(c1 - ring, 0), min(c1 + ring + 1, dims[1])):
                    for z in range(max(c2 - ring, 0), min(c2 + ring + 1, dims[2])):
                        if max(abs(x - c0), max(abs(y - c1), abs(z - c2))) != ring:
                            continue
                        if cnt == k and _box_d2(p, lo, size, x, y, z) > bd[k - 1]:
                            continue  # no point of this cell can be nearer than the k-th
                        c = (x * dims[1] + y) * dims[2] + z
                        for t in range(start[c], start[c + 1]):
                            if t == q:
                                continue
                            dx, dy, dz = p[0] - sp[t, 0], p[1] - sp[t, 1], p[2] - sp[t, 2]
                            cnt = _insert(bd, bi, cnt, dx * dx + dy * dy + dz * dz, items[t])
            bound = ring * size + margin
            if cnt == k and bd[k - 1] <= bound * bound:
                break
        out[i] = bi
    return out


@njit(cache=True)
def throw_darts(darts, prio, lo, r):
    """(M,) bool: the darts kept by dart throwing in ``prio`` order (none within ``r`` of another).

    A grid of cells of size ``r`` (so conflicts lie in the 3 x 3 x 3 block around a dart's cell),
    each cell a linked list of kept darts.
    """
    m = len(darts)
    cell = np.zeros((m, 3), np.int64)
    dims = np.zeros(3, np.int64)
    for i in range(m):
        for a in range(3):
            cell[i, a] = int((darts[i, a] - lo[a]) / r)
            dims[a] = max(dims[a], cell[i, a] + 1)
    head = np.full(dims[0] * dims[1] * dims[2], -1, np.int64)
    nxt = np.full(m, -1, np.int64)
    kept = np.zeros(m, np.bool_)
    order = np.argsort(prio)
    r2 = r * r
    for i in order:
        ok = True
        for cx in range(max(cell[i, 0] - 1, 0), min(cell[i, 0] + 2, dims[0])):
            for cy in range(max(cell[i, 1] - 1, 0), min(cell[i, 1] + 2, dims[1])):
                for cz in range(max(cell[i, 2] - 1, 0), min(cell[i, 2] + 2, dims[2])):
                    j = head[(cx * dims[1] + cy) * dims[2] + cz]
                    while j >= 0 and ok:
                        dx = darts[i, 0] - darts[j, 0]
                        dy = darts[i, 1] - darts[j, 1]
                        dz = darts[i, 2] - darts[j, 2]
                        ok = dx * dx + dy * dy + dz * dz > r2
                        j = nxt[j]
        if ok:
            kept[i] = True
            c = (cell[i, 0] * dims[1] + cell[i, 1]) * dims[2] + cell[i, 2]
            nxt[i], head[c] = head[c], i
    return kept
