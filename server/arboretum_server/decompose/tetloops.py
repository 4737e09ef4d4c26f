"""Compiled loops of the alpha shapes (lobes.py), each bit for bit the numpy reference kept beside it
(``*_reference``; tests/test_refine_s15_speed.py holds each pair together): circumspheres of tetrahedra,
which circumspheres hold a blocker point (the carving of ``Tetrahedra.without``), the boundary faces of
kept tetrahedra, and the closed-manifold test. Session 15: numpy's temporaries and scipy's sparse-graph
set-up took most of a refinement's hull time (an "around" insert on the pine: 116-122 -> 83-87 ms with
the rest of that change).
"""

from __future__ import annotations

import numpy as np

from arboretum_server.jitcache import njit


def circumspheres(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circumcentres (T, 3) and circumradii (T,) of tetrahedra ``p`` (T, 4, 3); inf radius (and nan
    centre) for flat ones.

    Closed form: with a, b, c the edges from vertex 0, the circumcentre offset is
    (|a|^2 (b x c) + |b|^2 (c x a) + |c|^2 (a x b)) / (2 a . (b x c)).
    A compiled loop, bit for bit ``circumspheres_reference`` (the tests hold the two together): numpy's
    temporaries took a fifth of a tetrahedralisation's time (session 15).
    """
    p = np.ascontiguousarray(p, dtype=np.float64)
    r = np.full(len(p), np.inf)
    centre = np.full((len(p), 3), np.nan)
    _circumspheres_kernel(p, centre, r)
    return centre, r


def circumspheres_reference(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``circumspheres`` in numpy (the slow reference)."""
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    bc, ca, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
    det = 2.0 * (a * bc).sum(axis=1)
    num = (a * a).sum(1)[:, None] * bc + (b * b).sum(1)[:, None] * ca + (c * c).sum(1)[:, None] * ab
    ok = np.abs(det) > 1e-18
    r = np.full(len(p), np.inf)
    centre = np.full((len(p), 3), np.nan)
    r[ok] = np.linalg.norm(num[ok], axis=1) / np.abs(det[ok])
    centre[ok] = p[ok, 0] + num[ok] / det[ok, None]
    return centre, r


@njit(cache=True, nogil=True)
def _circumspheres_kernel(p: np.ndarray, centre: np.ndarray, r: np.ndarray) -> None:  # pragma: no cover - numba
    """``circumspheres_reference`` tetrahedron by tetrahedron: the same float operations in the same order
    (``np.cross``'s products then difference, sums over three axes left to right)."""
    for t in range(p.shape[0]):
        a0, a1, a2 = p[t, 1, 0] - p[t, 0, 0], p[t, 1, 1] - p[t, 0, 1], p[t, 1, 2] - p[t, 0, 2]
        b0, b1, b2 = p[t, 2, 0] - p[t, 0, 0], p[t, 2, 1] - p[t, 0, 1], p[t, 2, 2] - p[t, 0, 2]
        c0, c1, c2 = p[t, 3, 0] - p[t, 0, 0], p[t, 3, 1] - p[t, 0, 1], p[t, 3, 2] - p[t, 0, 2]
        bc0, bc1, bc2 = b1 * c2 - b2 * c1, b2 * c0 - b0 * c2, b0 * c1 - b1 * c0
        ca0, ca1, ca2 = c1 * a2 - c2 * a1, c2 * a0 - c0 * a2, c0 * a1 - c1 * a0
        ab0, ab1, ab2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        det = 2.0 * (a0 * bc0 + a1 * bc1 + a2 * bc2)
        if not abs(det) > 1e-18:
            continue
        la, lb, lc = a0 * a0 + a1 * a1 + a2 * a2, b0 * b0 + b1 * b1 + b2 * b2, c0 * c0 + c1 * c1 + c2 * c2
        n0 = la * bc0 + lb * ca0 + lc * ab0
        n1 = la * bc1 + lb * ca1 + lc * ab1
        n2 = la * bc2 + lb * ca2 + lc * ab2
        r[t] = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2) / abs(det)
        centre[t, 0] = p[t, 0, 0] + n0 / det
        centre[t, 1] = p[t, 0, 1] + n1 / det
        centre[t, 2] = p[t, 0, 2] + n2 / det



def flat(p: np.ndarray, tol: float) -> np.ndarray:
    """(T,) bool: tetrahedra ``p`` (T, 4, 3) whose volume times 6 is not above ``tol`` times their longest
    edge cubed (``lobes.FLAT``). A compiled loop: numpy's (T, 6, 3) edge array cost a tenth of a
    dense lobe's hull (session 18)."""
    out = np.zeros(len(p), np.bool_)
    _flat_kernel(np.ascontiguousarray(p, dtype=np.float64), tol, out)
    return out


@njit(cache=True, nogil=True)
def _flat_kernel(p: np.ndarray, tol: float, out: np.ndarray) -> None:  # pragma: no cover - numba
    for t in range(p.shape[0]):
        longest = 0.0
        for i in range(4):
            for j in range(i + 1, 4):
                d0, d1, d2 = p[t, j, 0] - p[t, i, 0], p[t, j, 1] - p[t, i, 1], p[t, j, 2] - p[t, i, 2]
                longest = max(longest, d0 * d0 + d1 * d1 + d2 * d2)
        a0, a1, a2 = p[t, 1, 0] - p[t, 0, 0], p[t, 1, 1] - p[t, 0, 1], p[t, 1, 2] - p[t, 0, 2]
        b0, b1, b2 = p[t, 2, 0] - p[t, 0, 0], p[t, 2, 1] - p[t, 0, 1], p[t, 2, 2] - p[t, 0, 2]
        c0, c1, c2 = p[t, 3, 0] - p[t, 0, 0], p[t, 3, 1] - p[t, 0, 1], p[t, 3, 2] - p[t, 0, 2]
        six = abs(a0 * (b1 * c2 - b2 * c1) + a1 * (b2 * c0 - b0 * c2) + a2 * (b0 * c1 - b1 * c0))
        out[t] = not six > tol * longest * np.sqrt(longest)


HELD_CELLS = 12
"""``held`` buckets the blockers in a grid of at most this many cells along their box's longest side."""
HELD_MARGIN = 1e-9
"""Relative margin on squared distances within which ``held`` leaves the call to the KD-tree."""


def held(centres: np.ndarray, radii: np.ndarray, blockers: np.ndarray) -> np.ndarray:
    """(T,) int8 per sphere (``centres`` (T, 3), ``radii`` (T,)): 1 if it holds one of the ``blockers`` (B, 3),
    0 if not, 2 when a blocker lies within ``HELD_MARGIN`` of its surface (decided by the KD-tree query
    ``Tetrahedra.without`` made for every sphere before session 15: 2-3 times slower). Clear answers only
    (a squared distance off r^2 by a billionth cannot round across), so every answer is the KD-tree's."""
    out = np.zeros(len(centres), np.int8)
    if not len(centres) or not len(blockers):
        return out
    lo = blockers.min(axis=0)
    size = max(float((blockers.max(axis=0) - lo).max()) / HELD_CELLS, 1e-9)
    dims = ((blockers.max(axis=0) - lo) / size).astype(np.int64) + 1
    cell = np.minimum(((blockers - lo) / size).astype(np.int64), dims - 1)
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    first = np.r_[0, np.cumsum(np.bincount(key, minlength=int(np.prod(dims))))].astype(np.int64)
    _held_kernel(np.ascontiguousarray(centres), np.ascontiguousarray(radii), blockers[order], lo, size, dims,
                 first, HELD_MARGIN, out)
    return out


@njit(cache=True, nogil=True)
def _held_kernel(centres, radii, blockers, lo, size, dims, first, margin, out):  # pragma: no cover - numba
    span = np.zeros((3, 2), np.int64)
    for t in range(centres.shape[0]):
        r = radii[t]
        reach = r * (1.0 + 1e-6) + 1e-12  # a blocker within r (and the margin) lies in this box
        empty = False
        for k in range(3):
            a = (centres[t, k] - reach - lo[k]) / size
            b = (centres[t, k] + reach - lo[k]) / size
            if b < 0.0 or a >= dims[k]:
                empty = True
                break
            span[k, 0] = max(int(np.floor(a)), 0)
            span[k, 1] = min(int(np.floor(b)), dims[k] - 1)
        if empty:
            continue
        inner, outer = r * r * (1.0 - margin), r * r * (1.0 + margin)
        status = 0
        for ix in range(span[0, 0], span[0, 1] + 1):
            for iy in range(span[1, 0], span[1, 1] + 1):
                for iz in range(span[2, 0], span[2, 1] + 1):
                    c = (ix * dims[1] + iy) * dims[2] + iz
                    for i in range(first[c], first[c + 1]):
                        dx = blockers[i, 0] - centres[t, 0]
                        dy = blockers[i, 1] - centres[t, 1]
                        dz = blockers[i, 2] - centres[t, 2]
                        d2 = dx * dx + dy * dy + dz * dz
                        if d2 < inner:
                            status = 1
                            break
                        if d2 <= outer:
                            status = 2
                    if status == 1:
                        break
                if status == 1:
                    break
            if status == 1:
                break
        out[t] = status



def boundary(tets: np.ndarray, neighbours: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces (F, 3) of the kept ``tets`` (T, 4) whose neighbour across them (``neighbours`` (T, 4), the
    tetrahedron opposite each vertex, -1 for none) is not kept, and the vertex opposite each (F,).
    Face k of a tetrahedron is the one opposite its vertex k; faces come grouped by k, in tetrahedron order.
    A compiled loop (session 15), the same arrays as ``boundary_reference``."""
    tets = np.ascontiguousarray(tets)
    return _boundary_kernel(tets, np.ascontiguousarray(neighbours), np.ascontiguousarray(keep, dtype=np.bool_))


def boundary_reference(tets: np.ndarray, neighbours: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``boundary`` in numpy (the slow reference)."""
    out, opp = [], []
    for k, cols in enumerate(_FACE_COLUMNS):
        nb = neighbours[:, k]
        bnd = keep & ((nb < 0) | ~keep[nb])
        out.append(tets[bnd][:, list(cols)])
        opp.append(tets[bnd, k])
    return np.concatenate(out), np.concatenate(opp)


_FACE_COLUMNS = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))
"""The vertices of the face opposite vertex k of a tetrahedron, in the order ``boundary`` gives them."""


@njit(cache=True, nogil=True)
def _boundary_kernel(tets, neighbours, keep):  # pragma: no cover - numba
    cols = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    count = 0
    for k in range(4):
        for t in range(tets.shape[0]):
            nb = neighbours[t, k]
            count += keep[t] and (nb < 0 or not keep[nb])
    faces = np.zeros((count, 3), tets.dtype)
    opp = np.zeros(count, tets.dtype)
    i = 0
    for k in range(4):
        for t in range(tets.shape[0]):
            nb = neighbours[t, k]
            if keep[t] and (nb < 0 or not keep[nb]):
                for c in range(3):
                    faces[i, c] = tets[t, cols[k, c]]
                opp[i] = tets[t, k]
                i += 1
    return faces, opp



def is_closed_manifold(faces: np.ndarray, one_piece: bool = True) -> bool:
    """True when every edge of ``faces`` (F, 3) borders exactly two triangles and (``one_piece``) they form
    one piece (every vertex index up to the largest used is joined to the rest). A compiled loop (sorted
    edge keys, then union-find): the same answer as ``is_closed_manifold_reference`` (the tests hold the
    two together), without scipy's sparse-graph set-up, which took most of its time (session 15)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) < 4 or faces.min() < 0:  # numba wraps a negative index: no answer from garbage
        return False
    return bool(_closed_kernel(faces, int(faces.max()) + 1, one_piece))


def is_closed_manifold_reference(faces: np.ndarray, one_piece: bool = True) -> bool:
    """``is_closed_manifold`` with ``np.unique`` and scipy's connected components (the slow reference)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) < 4:
        return False
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1).astype(np.int64)
    _, counts = np.unique(e[:, 0] * (int(faces.max()) + 1) + e[:, 1], return_counts=True)
    if (counts != 2).any():
        return False
    if not one_piece:
        return True
    n = int(faces.max()) + 1
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[0] == 1


@njit(cache=True, nogil=True)
def _closed_kernel(faces: np.ndarray, n: int, one_piece: bool) -> bool:  # pragma: no cover - numba
    keys = np.zeros(3 * faces.shape[0], np.int64)
    for t in range(faces.shape[0]):
        for k in range(3):
            u, v = faces[t, k], faces[t, (k + 1) % 3]
            keys[3 * t + k] = min(u, v) * n + max(u, v)
    keys.sort()
    i = 0
    while i < len(keys):  # every key exactly twice
        if i + 1 >= len(keys) or keys[i + 1] != keys[i] or (i + 2 < len(keys) and keys[i + 2] == keys[i]):
            return False
        i += 2
    if not one_piece:
        return True
    root = np.arange(n)
    pieces = n
    for i in range(0, len(keys), 2):
        u, v = keys[i] // n, keys[i] % n
        while root[u] != u:
            root[u] = root[root[u]]
            u = root[u]
        while root[v] != v:
            root[v] = root[root[v]]
            v = root[v]
        if u != v:
            root[u] = v
            pieces -= 1
    return pieces == 1


def covered(tets: np.ndarray, keep: np.ndarray, n: int) -> int:
    """How many of the ``n`` points are a corner of a kept tetrahedron (``tets`` (T, 4), ``keep`` (T,) bool).
    A compiled loop, the same count as ``covered_reference`` (session 26: the gather of the kept
    tetrahedra took a third of an alpha shape's time)."""
    return int(_covered_kernel(np.ascontiguousarray(tets), np.ascontiguousarray(keep, dtype=np.bool_), n))


def covered_reference(tets: np.ndarray, keep: np.ndarray, n: int) -> int:
    """``covered`` in numpy (the code before)."""
    used = np.zeros(n, bool)
    used[tets[keep].ravel()] = True
    return int(used.sum())


@njit(cache=True, nogil=True)
def _covered_kernel(tets, keep, n):  # pragma: no cover - numba
    used = np.zeros(n, np.bool_)
    count = 0
    for t in range(tets.shape[0]):
        if keep[t]:
            for c in range(4):
                v = tets[t, c]
                if not used[v]:
                    used[v] = True
                    count += 1
    return count


def orient(points: np.ndarray, faces: np.ndarray, opp: np.ndarray) -> np.ndarray:
    """``faces`` (F, 3) with the last two corners swapped on each face whose normal (``np.cross`` of its
    edges from corner 0) points towards its opposite vertex ``opp`` (F,): every face then faces away from
    its tetrahedron. A compiled loop, the same float operations as ``orient_reference`` (``np.cross``'s
    products then difference, the dot product summed left to right), so the same faces."""
    out = np.ascontiguousarray(faces).copy()
    _orient_kernel(np.ascontiguousarray(points, dtype=np.float64), out, np.ascontiguousarray(opp))
    return out


def orient_reference(points: np.ndarray, faces: np.ndarray, opp: np.ndarray) -> np.ndarray:
    """``orient`` in numpy (the code before)."""
    faces = faces.copy()
    f = points[faces]
    n = np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0])
    flip = ((points[opp] - f[:, 0]) * n).sum(axis=1) > 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


@njit(cache=True, nogil=True)
def _orient_kernel(p, faces, opp):  # pragma: no cover - numba
    for i in range(faces.shape[0]):
        a, b, c, o = faces[i, 0], faces[i, 1], faces[i, 2], opp[i]
        u0, u1, u2 = p[b, 0] - p[a, 0], p[b, 1] - p[a, 1], p[b, 2] - p[a, 2]
        v0, v1, v2 = p[c, 0] - p[a, 0], p[c, 1] - p[a, 1], p[c, 2] - p[a, 2]
        n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        d0, d1, d2 = p[o, 0] - p[a, 0], p[o, 1] - p[a, 1], p[o, 2] - p[a, 2]
        if (d0 * n0 + d1 * n1) + d2 * n2 > 0:
            faces[i, 1], faces[i, 2] = c, b


def drop_edges(tets: np.ndarray, keep: np.ndarray, edges: np.ndarray) -> None:
    """Clear ``keep`` (T,) bool, in place, at the kept tetrahedra (``tets`` (T, 4)) holding one of ``edges``
    (sorted unique keys ``lo * 2**32 + hi``, ``lobes._edge_keys``). A compiled loop (binary search per
    edge), the same mask as ``drop_edges_reference``."""
    _drop_kernel(np.ascontiguousarray(tets), keep, np.ascontiguousarray(edges, dtype=np.int64))


def drop_edges_reference(tets: np.ndarray, keep: np.ndarray, edges: np.ndarray) -> None:
    """``drop_edges`` with ``np.isin`` over every kept tetrahedron's six edge keys (the code before)."""
    kept = tets[keep]
    a, b = kept[:, [0, 0, 0, 1, 1, 2]].ravel(), kept[:, [1, 2, 3, 2, 3, 3]].ravel()
    lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
    keep[keep] = ~np.isin(lo * (1 << 32) + hi, edges).reshape(-1, 6).any(axis=1)


@njit(cache=True, nogil=True)
def _drop_kernel(tets, keep, edges):  # pragma: no cover - numba
    ea = (0, 0, 0, 1, 1, 2)
    eb = (1, 2, 3, 2, 3, 3)
    for t in range(tets.shape[0]):
        if not keep[t]:
            continue
        for k in range(6):
            a, b = np.int64(tets[t, ea[k]]), np.int64(tets[t, eb[k]])
            key = min(a, b) * (np.int64(1) << 32) + max(a, b)
            i = np.searchsorted(edges, key)
            if i < edges.shape[0] and edges[i] == key:
                keep[t] = False
                break


def pinched_edges(faces: np.ndarray) -> np.ndarray:
    """Keys (sorted, int64) of the edges that border more than two of ``faces`` (F, 3) (indices < 2**31): what
    ``lobes._pinched_edges_reference`` gives with ``np.unique``, in one compiled call (session 29: a carving
    asks it up to ``PINCH_ROUNDS`` times per probe radius, 60 us each in numpy)."""
    return _pinched_kernel(np.ascontiguousarray(faces).reshape(-1, 3))


@njit(cache=True, nogil=True)
def _pinched_kernel(faces):  # pragma: no cover - numba
    n = faces.shape[0]
    keys = np.zeros(3 * n, np.int64)
    for i in range(3):
        for t in range(n):
            a, b = np.int64(faces[t, i]), np.int64(faces[t, (i + 1) % 3])
            keys[i * n + t] = min(a, b) * 4294967296 + max(a, b)
    keys.sort()
    out = np.zeros(len(keys), np.int64)
    m, i = 0, 0
    while i < len(keys):
        k = i
        while k < len(keys) and keys[k] == keys[i]:
            k += 1
        if k - i > 2:
            out[m] = keys[i]
            m += 1
        i = k
    return out[:m].copy()


def compact(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(the points ``faces`` (F, 3) use, in index order; the faces renumbered into them, int32): what
    ``lobes._compact_reference`` gives (a mask of the used points and its running count), in one compiled call
    (session 29: a split into 100 pieces compacts 100-200 shapes, 30 us each in numpy). None when a face index
    lies outside ``points`` (the caller then asks numpy, which wraps or raises as before)."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        return None
    ok, verts, out = _compact_kernel(pts, np.ascontiguousarray(faces).reshape(-1, 3))
    return (verts, out) if ok else None


@njit(cache=True, nogil=True)
def _compact_kernel(points, faces):  # pragma: no cover - numba
    n = points.shape[0]
    mark = np.zeros(n, np.bool_)
    for t in range(faces.shape[0]):
        for k in range(3):
            v = faces[t, k]
            if v < 0 or v >= n:
                return False, np.zeros((0, 3)), np.zeros((0, 3), np.int32)
            mark[v] = True
    rank = np.zeros(n, np.int64)
    used = 0
    for i in range(n):
        if mark[i]:
            used += 1
        rank[i] = used - 1
    verts = np.zeros((used, 3))
    for i in range(n):
        if mark[i]:
            verts[rank[i]] = points[i]
    out = np.zeros((faces.shape[0], 3), np.int32)
    for t in range(faces.shape[0]):
        for k in range(3):
            out[t, k] = rank[faces[t, k]]
    return True, verts, out


def warm() -> None:
    """Run every loop here once on a tiny input of the dtypes the alpha shapes use (scipy's int32
    simplices), so numba loads or compiles them now: the service calls it when it starts
    (``dispatch.warm_up``), not inside a user's first refinement."""
    p = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    centre, r = circumspheres(p)
    flat(p, 1e-10)
    held(centre, r, np.zeros((1, 3)))
    boundary(np.array([[0, 1, 2, 3]], np.int32), np.full((1, 4), -1, np.int32), np.ones(1, bool))
    is_closed_manifold(np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    tet, keep = np.array([[0, 1, 2, 3]], np.int32), np.ones(1, bool)
    covered(tet, keep, 4)
    orient(p[0], tet[:, :3], tet[:, 3])
    drop_edges(tet, keep, np.array([1], np.int64))
    pinched_edges(tet[:, :3])
    compact(p[0], tet[:, :3])
