"""Many closed hulls tested at once: every hull's faces with their XY boxes and top packed once into flat
arrays (``HullPack``), then points (``inside_any``) or sampled segments (``segments_blocked``) tested in one
compiled loop that stops at the first hull holding a point. Each answer is the one ``lobes.inside`` gives
hull by hull (the same ray-crossing count, ``lobes._crossings_of``), for the refinement repairs
(``clear.inside_foreign``, ``clear.blocked``) that ask it of every lobe of a tree many times over.

Each hull's faces are also bucketed in an XY grid of its box (``_grid_of``, ``_bucket``): a point's ray meets
only faces whose XY box holds it, and all of those lie in the point's cell (``_cell`` never decreases as a
coordinate grows), so a test reads that cell's faces alone, the
same crossings summed (session 23: with about 2 faces a cell, the leaf-on pine's slowest split into 20 went
from 224 to 173 ms; the loops read every face of every hull a sample's box test let through).

``any_inside`` answers only whether any point is inside, up to the first one (``clear.foreign``'s question),
and the point loops try only the hulls whose box meets the points' box (``_hulls_meeting``; session 27).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from arboretum_server.jitcache import njit

from .lobes import face_crossing
from .merge import _resample_kernel


class HullPack(NamedTuple):
    """Several closed hulls in flat arrays for ``inside_any`` and ``segments_blocked``: every hull's faces
    with their XY boxes and top, computed once per set of hulls instead of once per query."""

    vertices: np.ndarray
    """(V, 3) float64: every hull's vertices, hull after hull."""
    faces: np.ndarray
    """(F, 3) int64: every hull's faces, as indices into ``vertices`` (each hull's order kept)."""
    first: np.ndarray
    """(H + 1,) int64: hull h owns faces first[h]:first[h + 1]."""
    face_lo: np.ndarray
    """(F, 2) float64: each face's smallest x and y."""
    face_hi: np.ndarray
    """(F, 2) float64: each face's largest x and y."""
    face_top: np.ndarray
    """(F,) float64: each face's largest z."""
    grid: np.ndarray
    """(H, 6) float64: each hull's XY grid: lowest x and y, cells per unit of x and y, cells along x and y."""
    cell_first: np.ndarray
    """(H + 1,) int64: hull h's cells are cell_start[cell_first[h]:cell_first[h + 1]] (x-major)."""
    cell_start: np.ndarray
    """(C + 1,) int64: cell c holds the faces cell_faces[cell_start[c]:cell_start[c + 1]]."""
    cell_faces: np.ndarray
    """(E,) int64: face indices (into ``faces``), cell after cell, ascending within a cell."""


def pack_hull(vertices: np.ndarray, faces: np.ndarray) -> HullPack:
    """The ``HullPack`` of one hull (vertices (V, 3), faces (F, 3)). Its face boxes and grid are made in one
    compiled call (``_face_boxes``, ``_grid_of``: the same numbers as the numpy they replace; session 23: 27
    -> 6 us a hull, which a split into 100 pieces pays for 100 new hulls)."""
    verts = np.array(vertices, dtype=np.float64).reshape(-1, 3)  # a copy: a cache keyed by the hull's arrays holds it
    faces = np.array(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(verts)):  # the kernels check no bounds
        raise ValueError(f"pack_hull: face indices {faces.min()}..{faces.max()} for {len(verts)} vertices")
    if not len(faces):  # no face: one empty cell
        return HullPack(verts, faces, np.array([0, 0], np.int64), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0),
                        np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 1.0]]), np.array([0, 1], np.int64), np.zeros(2, np.int64),
                        np.zeros(0, np.int64))
    flo, fhi, ftop = _face_boxes(verts, faces)
    grid = _grid_of(verts, len(faces), float(FACES_PER_CELL), int(GRID_MAX))
    start, cells = _bucket(grid, flo, fhi)
    return HullPack(verts, faces, np.array([0, len(faces)], np.int64), flo, fhi, ftop, grid[None],
                    np.array([0, len(start) - 1], np.int64), start, cells)


@njit(cache=True)
def _face_boxes(verts, faces):  # pragma: no cover - numba
    """Each face's smallest x and y (F, 2), largest x and y (F, 2) and largest z (F,)."""
    n = faces.shape[0]
    flo, fhi, ftop = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(n)
    for t in range(n):
        a, b, c = verts[faces[t, 0]], verts[faces[t, 1]], verts[faces[t, 2]]
        for k in range(2):
            flo[t, k] = min(a[k], b[k], c[k])
            fhi[t, k] = max(a[k], b[k], c[k])
        ftop[t] = max(a[2], b[2], c[2])
    return flo, fhi, ftop


@njit(cache=True)
def _grid_of(verts, n_faces, per_cell, most):  # pragma: no cover - numba
    """The grid (6,) of a hull with faces (see ``HullPack.grid``), compiled: (faces / ``per_cell``) ** 0.5 cells along x
    and y (1 to ``most``), over the XY box of all its vertices."""
    lo = np.zeros(2)
    span = np.zeros(2)
    for k in range(2):
        lo[k] = verts[:, k].min()
        span[k] = verts[:, k].max() - lo[k]
    n = int(min(max(np.sqrt(n_faces / per_cell), 1.0), float(most)))
    grid = np.zeros(6)
    for k in range(2):
        per = n / span[k] if span[k] > 0 else 0.0
        grid[k], grid[2 + k], grid[4 + k] = lo[k], per if np.isfinite(per) else 0.0, n
    return grid


FACES_PER_CELL = 2.0
"""``_grid_of`` makes about (faces / this) cells per hull (at most ``GRID_MAX`` along x or y)."""
GRID_MAX = 64


@njit(cache=True)
def _cell(grid, h, x, k) -> int:  # pragma: no cover - numba
    """The cell along axis ``k`` (0: x, 1: y) of coordinate ``x`` in grid row ``h`` (clamped to the grid, in
    floats first: no integer conversion of an overflow)."""
    f = (x - grid[h, k]) * grid[h, 2 + k]
    last = grid[h, 4 + k] - 1
    if not f > 0.0:
        return 0
    return int(last) if f >= last else int(f)


@njit(cache=True)
def _bucket(grid, flo, fhi):  # pragma: no cover - numba
    g = grid.reshape(1, 6)
    nx, ny = int(grid[4]), int(grid[5])
    count = np.zeros(nx * ny + 1, np.int64)
    for pass_ in range(2):
        if pass_ == 1:
            for c in range(nx * ny):
                count[c + 1] += count[c]
            cells = np.zeros(count[nx * ny], np.int64)
            fill = count.copy()
        for t in range(flo.shape[0]):
            for cx in range(_cell(g, 0, flo[t, 0], 0), _cell(g, 0, fhi[t, 0], 0) + 1):
                for cy in range(_cell(g, 0, flo[t, 1], 1), _cell(g, 0, fhi[t, 1], 1) + 1):
                    if pass_ == 0:
                        count[cx * ny + cy + 1] += 1
                    else:
                        cells[fill[cx * ny + cy]] = t
                        fill[cx * ny + cy] += 1
    return count, cells


def join_packs(packs: list[HullPack]) -> HullPack:
    """One ``HullPack`` of the hulls of ``packs`` (one hull each), in order. Each array is joined once and its
    offsets added in one step (session 24: an addition per hull and field made a join of 59 hulls 0.8 ms,
    which a split into 20 paid 16 times as carving changed hulls; the same integers)."""
    if not packs:
        empty = pack_hull(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
        return empty._replace(first=np.zeros(1, np.int64), grid=np.zeros((0, 6)),
                              cell_first=np.zeros(1, np.int64))  # no hull at all, not one empty hull
    n_verts = np.array([len(p.vertices) for p in packs], np.int64)
    n_faces = np.array([len(p.faces) for p in packs], np.int64)
    n_cells = np.array([len(p.cell_start) - 1 for p in packs], np.int64)
    n_entries = np.array([len(p.cell_faces) for p in packs], np.int64)
    face_shift = np.r_[0, np.cumsum(n_faces)].astype(np.int64)
    entry_shift = np.r_[0, np.cumsum(n_entries)].astype(np.int64)
    faces = np.concatenate([p.faces for p in packs]).astype(np.int64, copy=False)
    faces = faces + np.repeat(np.r_[0, np.cumsum(n_verts)[:-1]], n_faces)[:, None]
    starts = np.concatenate([p.cell_start[:-1] for p in packs]).astype(np.int64, copy=False)
    starts = np.r_[starts + np.repeat(entry_shift[:-1], n_cells), entry_shift[-1]]
    cell_faces = np.concatenate([p.cell_faces for p in packs]).astype(np.int64, copy=False)
    cell_faces = cell_faces + np.repeat(face_shift[:-1], n_entries)
    return HullPack(np.concatenate([p.vertices for p in packs]), faces, face_shift,
                    np.concatenate([p.face_lo for p in packs]), np.concatenate([p.face_hi for p in packs]),
                    np.concatenate([p.face_top for p in packs]), np.concatenate([p.grid for p in packs]),
                    np.r_[0, np.cumsum(n_cells)].astype(np.int64), starts.astype(np.int64), cell_faces)


def vertex_first(packs: list[HullPack]) -> np.ndarray:
    """(H + 1,) int64: where each hull's vertices start in ``join_packs(packs)``'s vertices (for ``splice_packs``)."""
    return np.r_[0, np.cumsum([len(p.vertices) for p in packs])].astype(np.int64)


def splice_packs(old: HullPack, vfirst: np.ndarray, new: dict[int, HullPack]) -> HullPack:
    """``join_packs(packs)``, the same arrays, where ``packs[h]`` is ``old``'s hull h (``old`` a ``join_packs``
    result, ``vfirst`` its ``vertex_first``) except the hulls ``new[h]`` (one hull each) that replace it: each
    run of unchanged hulls is copied from ``old`` whole, its indices shifted by the change in its offsets, so a
    pack with 1-3 of 60 hulls carved again costs a copy of each array instead of a join of 60 hulls (session 29;
    the same integer sums, so the same numbers)."""
    n_hulls = len(old.first) - 1
    o_v, o_f, o_c = vfirst, old.first, old.cell_first
    o_e = old.cell_start[o_c]
    counts = [np.diff(o_v), np.diff(o_f), np.diff(o_c), np.diff(o_e)]
    for i, p in new.items():
        for k, n in enumerate((len(p.vertices), len(p.faces), len(p.cell_start) - 1, len(p.cell_faces))):
            counts[k][i] = n
    v_at, f_at, c_at, e_at = (np.r_[0, np.cumsum(n)].astype(np.int64) for n in counts)
    verts, faces = np.zeros((v_at[-1], 3)), np.zeros((f_at[-1], 3), np.int64)
    flo, fhi, ftop = np.zeros((f_at[-1], 2)), np.zeros((f_at[-1], 2)), np.zeros(f_at[-1])
    grid, starts, cells = np.zeros((n_hulls, 6)), np.zeros(c_at[-1] + 1, np.int64), np.zeros(e_at[-1], np.int64)
    for a, b, p in _runs(n_hulls, new):
        fs, cs, es = slice(f_at[a], f_at[b]), slice(c_at[a], c_at[b]), slice(e_at[a], e_at[b])
        if p is None:  # hulls a..b-1 of ``old``
            of, oc, oe = slice(o_f[a], o_f[b]), slice(o_c[a], o_c[b]), slice(o_e[a], o_e[b])
            verts[v_at[a]:v_at[b]] = old.vertices[o_v[a]:o_v[b]]
            np.add(old.faces[of], v_at[a] - o_v[a], out=faces[fs])
            flo[fs], fhi[fs], ftop[fs], grid[a:b] = old.face_lo[of], old.face_hi[of], old.face_top[of], old.grid[a:b]
            np.add(old.cell_start[oc], e_at[a] - o_e[a], out=starts[cs])
            np.add(old.cell_faces[oe], f_at[a] - o_f[a], out=cells[es])
        else:  # hull a replaced: placed as ``join_packs`` places it
            verts[v_at[a]:v_at[b]] = p.vertices
            np.add(p.faces, v_at[a], out=faces[fs])
            flo[fs], fhi[fs], ftop[fs], grid[a:b] = p.face_lo, p.face_hi, p.face_top, p.grid
            np.add(p.cell_start[:-1], e_at[a], out=starts[cs])
            np.add(p.cell_faces, f_at[a], out=cells[es])
    starts[-1] = e_at[-1]
    return HullPack(verts, faces, f_at, flo, fhi, ftop, grid, c_at, starts, cells)


def _runs(n_hulls: int, new: dict[int, HullPack]) -> list[tuple[int, int, HullPack | None]]:
    """(a, b, pack): the hulls 0..``n_hulls - 1`` in runs of unchanged ones (pack None) and single replaced ones."""
    out: list[tuple[int, int, HullPack | None]] = []
    h = 0
    for i in sorted(new):
        if i > h:
            out.append((h, i, None))
        out.append((i, i + 1, new[i]))
        h = i + 1
    if h < n_hulls:
        out.append((h, n_hulls, None))
    return out


def inside_any(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, q: np.ndarray) -> tuple[np.ndarray, int]:
    """((M,) bool, hull tests): which ``q`` (M, 3) lie inside a hull of ``pack`` other than ``skip``, each
    hull tried only for points strictly inside its box (``lo``, ``hi`` (H, 3)) and only until one holds the
    point. The same answer as ``inside`` hull by hull; the count is of (point, hull) tests made."""
    q = _writable(q, np.float64).reshape(-1, 3)
    out = np.zeros(len(q), np.bool_)
    tests = _inside_any_kernel(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi, pack.face_top,
                               _read_only(lo), _read_only(hi), int(skip), q, out)
    return out, int(tests)


def segments_blocked(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, start: np.ndarray, end: np.ndarray,
                     counts: np.ndarray, stride: int = 4, until_clear: bool = False,
                     start_ids: np.ndarray | None = None, prior: np.ndarray | None = None,
                     by: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """((S,) bool, hull tests): which segments ``start`` -> ``end`` ((S, 3) each), sampled at ``counts``
    (S,) evenly spaced points from end to end (``np.linspace``), have a sample inside a hull of ``pack``
    other than ``skip`` (as ``inside_any``). Each segment's every ``stride``-th sample is tried first,
    and a segment stops at its first sample inside a hull: the answer of testing every sample, for the
    work of the samples up to that one (the samples are made here, only as far as they are needed).
    ``until_clear``: the segments are tried in order up to the first clear one only (the callers that take
    the first clear segment); the ones after it are left True, untried.
    ``start_ids`` (S,) ints >= 0, equal for segments with the same start (e.g. the main vertex's index): a
    start's first sample is tested once (the same answers and counts); by default, runs of equal starts.
    ``prior`` (S,) ints: a hull known to hold one of segment i's samples, whose box here is its own and strictly
    holds that sample (-1: none known): the segment is blocked, no hull tried (session 25: the repairs test the
    same segments again after a carving that left the hull blocking them as it was). ``by`` (S,) ints, filled
    when given: the hull holding the sample that blocked segment i (-1 for a clear or untried one)."""
    ids = _NO_IDS if start_ids is None else _writable(start_ids, np.int64)
    out = np.zeros(len(start), np.bool_)
    tests = _segments_kernel(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi, pack.face_top,
                             _read_only(lo), _read_only(hi), int(skip), _writable(start, np.float64),
                             _writable(end, np.float64), _writable(counts, np.int64), int(stride), out,
                             bool(until_clear), ids, int(ids.max()) + 1 if len(ids) else len(start),
                             _NO_IDS if prior is None else _writable(prior, np.int64),
                             np.full(len(start), -1, np.int64) if by is None else by)
    return out, int(tests)


_NO_IDS = np.zeros(0, np.int64)
"""``_segments_kernel``'s start ids when the caller gives none: runs of equal starts, numbered in the kernel."""


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous float64 array, read only (a view when it is writable): the boxes come read only
    from ``clear._packed`` and writable from callers that pass their own, and numba compiles a kernel once
    per kind, so the kernels see one kind only (the one ``warm`` compiles)."""
    a = np.ascontiguousarray(a, np.float64)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


def _writable(a: np.ndarray, dtype: type) -> np.ndarray:
    """``a`` as a C-contiguous array of ``dtype``, writable (a copy when it is read only, as shared arrays are):
    the kernels' one compiled kind for the queries (see ``_read_only``)."""
    a = np.ascontiguousarray(a, dtype)
    return a if a.flags.writeable else a.copy()


def _cells(pack: HullPack) -> tuple:
    """The grid arrays the kernels read (one argument)."""
    return pack.grid, pack.cell_first, pack.cell_start, pack.cell_faces


@njit(cache=True)
def _point_inside(v, f, cells, flo, fhi, ftop, lo, hi, skip, x, y, z, tests) -> bool:  # pragma: no cover
    """True if (x, y, z) lies inside a hull other than ``skip`` whose box strictly holds it; ``tests[0]``
    counts the hulls tried. A hull's crossings are summed over the faces of the point's grid cell only.
    The box test stays here, the face loop is ``_hull_holds``' (a call holding the box test too made this
    kernel 25 times slower: session 23, helper-165). ``_inside_any_kernel``'s test of a point before session 27
    (it now tries the hulls of ``_hulls_meeting`` alone, ``_sample_hull``): the tests' reference."""
    grid, cell_first, cell_start, cell_faces = cells
    for k in range(grid.shape[0]):
        if k == skip or not (lo[k, 0] < x < hi[k, 0] and lo[k, 1] < y < hi[k, 1] and lo[k, 2] < z < hi[k, 2]):
            continue
        tests[0] += 1
        if _hull_holds(v, f, cells, flo, fhi, ftop, k, x, y, z):
            return True
    return False


@njit(cache=True)
def _hull_holds(v, f, cells, flo, fhi, ftop, k, x, y, z) -> bool:  # pragma: no cover
    """True if hull ``k`` holds (x, y, z): its crossings summed over the faces of the point's grid cell only
    (``_point_inside``'s test of one hull, for ``_segments_kernel``)."""
    grid, cell_first, cell_start, cell_faces = cells
    c = cell_first[k] + _cell(grid, k, x, 0) * int(grid[k, 5]) + _cell(grid, k, y, 1)
    total = 0
    for e in range(cell_start[c], cell_start[c + 1]):
        t = cell_faces[e]
        if x < flo[t, 0] or x > fhi[t, 0] or y < flo[t, 1] or y > fhi[t, 1] or z > ftop[t]:
            continue  # the ray misses the face (as in lobes._crossings_of)
        total += face_crossing(v, f, t, x, y, z)
    return total > 0


@njit(cache=True)
def _inside_any_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, q, out) -> int:  # pragma: no cover
    """``_point_inside`` of every point of ``q`` (into ``out``), with the hulls tried listed once per call: those
    whose box meets the points' box (``_hulls_meeting``), ascending (session 27: a call's points are a
    resampled branch, whose box meets a few of the tree's 60 lobe boxes; the same hulls tried per point, in
    the same order, so the same answers and count)."""
    tests = np.zeros(1, np.int64)
    near = np.zeros(lo.shape[0], np.int64)
    n_near = _hulls_meeting(lo, hi, skip, q, near)
    for i in range(q.shape[0]):
        out[i] = _sample_hull(v, f, cells, flo, fhi, ftop, lo, hi, near, n_near, q[i, 0], q[i, 1], q[i, 2], tests) >= 0
    return tests[0]


def any_inside(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, q: np.ndarray,
               stride: int = 4) -> tuple[bool, int]:
    """(True if one of ``q`` (M, 3) lies inside a hull of ``pack`` other than ``skip``, hull tests):
    ``inside_any(...)[0].any()``, the points tried every ``stride``-th first, then the rest, up to the first
    one inside (session 27: ``clear.foreign`` asks only whether any is; most of the routes ``tunnel.along``
    tries are blocked, and their blocked samples show up early). Each point is tested as ``inside_any`` tests
    it; only the count of tests differs (the points after the first inside are not tried)."""
    q = _writable(q, np.float64).reshape(-1, 3)
    found, tests = _any_inside_kernel(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi,
                                      pack.face_top, _read_only(lo), _read_only(hi), int(skip), q, int(stride))
    return bool(found), int(tests)


@njit(cache=True)
def _any_inside_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, q, stride):  # pragma: no cover
    """``any_inside``'s loop, (found, hull tests): every ``stride``-th point, then the rest, each tried against
    the hulls whose box meets the points' box (``_hulls_meeting``) up to the first point inside one."""
    tests = np.zeros(1, np.int64)
    near = np.zeros(lo.shape[0], np.int64)
    n_near = _hulls_meeting(lo, hi, skip, q, near)
    if n_near == 0:
        return False, tests[0]
    for phase in range(2):
        for i in range(q.shape[0]):
            if (i % stride == 0) != (phase == 0):
                continue
            if _sample_hull(v, f, cells, flo, fhi, ftop, lo, hi, near, n_near, q[i, 0], q[i, 1], q[i, 2], tests) >= 0:
                return True, tests[0]
    return False, tests[0]


def any_inside_along(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, seg: np.ndarray, tol: float,
                     stride: int = 4) -> tuple[bool, int, bool]:
    """(found, hull tests, done): ``any_inside(pack, lo, hi, skip, merge.resample_step(seg, tol))`` in one compiled
    call (``clear.foreign``'s question, asked hundreds of times a split: session 29), the same samples
    (``merge._resample_kernel``) and the same hull tests. ``done`` False (nothing tested): ``seg`` is one that
    ``resample_step`` leaves to its numpy reference (not (N >= 2, 3), ``tol`` not > 0, a non-finite length); the
    caller asks it the old way."""
    pts = np.ascontiguousarray(seg, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2 or not (tol > 0):
        return False, 0, False
    found, tests, done = _along_inside_kernel(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi,
                                              pack.face_top, _read_only(lo), _read_only(hi), int(skip),
                                              pts if pts.flags.writeable else pts.copy(), float(tol), int(stride))
    return bool(found), int(tests), bool(done)


@njit(cache=True)
def _along_inside_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, seg, tol, stride):  # pragma: no cover
    """``any_inside_along``'s call: ``seg`` resampled, then ``_any_inside_kernel``; (False, 0, False) when the
    resampling gives nothing."""
    q = _resample_kernel(seg, tol)
    if q.shape[0] == 0:
        return False, 0, False
    found, tests = _any_inside_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, q, stride)
    return found, tests, True


def first_clear_route(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, seg: np.ndarray,
                      centre: np.ndarray, order: np.ndarray, counts: np.ndarray, tol: float,
                      stride: int = 4, clear: np.ndarray | None = None) -> tuple[int, int, int]:
    """(i, hull tests, resume): the first i whose route ``seg[:order[i]]`` then ``counts[i]`` points evenly from
    ``seg[order[i]]`` to ``centre`` (``np.linspace``) has no vertex, resampled every ``tol``
    (``merge.resample_step``), inside a hull other than ``skip`` (``any_inside``), -1 for none; the routes after
    it are not made. ``tunnel.along``'s routes made and tested in one compiled call, the same floats and the
    same hull tests as one ``clear.foreign`` call per route (session 28). ``resume`` >= 0: route ``resume``
    resampled to nothing (a non-finite length: ``resample_step``'s reference handles it), left to the caller
    with every route after it (``i`` is then -1 and the tests are those of the routes before it).
    ``clear`` (R,) bool, when given: every route is tried (none is left untried after a clear one; ``i`` is then
    -1) and ``clear[i]`` set True for each clear one."""
    seg = _writable(seg, np.float64).reshape(-1, 3)
    every = clear is not None
    return _routes_kernel(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi, pack.face_top,
                          _read_only(lo), _read_only(hi), int(skip), seg, _writable(centre, np.float64).reshape(3),
                          _writable(order, np.int64), _writable(counts, np.int64), float(tol), int(stride),
                          clear if every else np.zeros(len(order), np.bool_), every)


def clear_prefix(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, seg: np.ndarray, tol: float,
                 stride: int = 4) -> tuple[int, int, int]:
    """(ok, hull tests, resume): how many of the prefixes ``seg[:1]``, ``seg[:2]``, ... in turn have no vertex,
    resampled every ``tol``, inside a hull other than ``skip``, up to the first that has one (one
    ``clear.foreign`` call per prefix, as ``tunnel._clear_prefix`` made them, in one compiled call; a one-point
    prefix resampled as ``resample_step`` does, to that point twice). ``resume`` >= 0: prefix ``resume + 1``
    resampled to nothing (left to the caller, as in ``first_clear_route``; ``ok`` is then ``resume``)."""
    seg = _writable(seg, np.float64).reshape(-1, 3)
    return _prefix_kernel(pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi, pack.face_top,
                          _read_only(lo), _read_only(hi), int(skip), seg, float(tol), int(stride))


@njit(cache=True)
def _routes_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, seg, centre, order, counts, tol,
                   stride, clear, every):  # pragma: no cover - numba
    """``first_clear_route``'s loop: each route made as ``tunnel._along_route_iter`` makes it (the prefix, then
    ``seg[w] + t * (centre - seg[w])`` for ``np.linspace``'s t = i * (1 / (m - 1)), the last 1), resampled by
    ``merge._resample_kernel`` and tried by ``_any_inside_kernel``."""
    tests = 0
    for i in range(order.shape[0]):
        q = _resample_kernel(_along_route_kernel(seg, centre, order[i], counts[i]), tol)
        if q.shape[0] == 0:
            return -1, tests, i
        found, n = _any_inside_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, q, stride)
        tests += n
        clear[i] = not found
        if not found and not every:
            return i, tests, -1
    return -1, tests, -1


@njit(cache=True)
def _along_route_kernel(seg, centre, w, m):  # pragma: no cover - numba
    """``tunnel._along_route(seg, centre, w, m)`` bit for bit: ``seg[:w]``, then ``seg[w] + t * (centre - seg[w])``
    for ``np.linspace(0, 1, m)``'s t (i * (1 / (m - 1)) + 0, the last 1)."""
    route = np.zeros((w + m, 3))
    route[:w] = seg[:w]
    step = 1.0 / (m - 1)
    d0, d1, d2 = centre[0] - seg[w, 0], centre[1] - seg[w, 1], centre[2] - seg[w, 2]
    for r in range(m):
        t = 1.0 if r == m - 1 else r * step + 0.0
        route[w + r, 0] = seg[w, 0] + t * d0
        route[w + r, 1] = seg[w, 1] + t * d1
        route[w + r, 2] = seg[w, 2] + t * d2
    return route


@njit(cache=True)
def _prefix_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, seg, tol, stride):  # pragma: no cover - numba
    """``clear_prefix``'s loop: each prefix resampled by ``merge._resample_kernel`` (a one-point prefix as that
    point twice) and tried by ``_any_inside_kernel``."""
    tests = 0
    for ok in range(seg.shape[0]):
        if ok == 0:
            q = np.zeros((2, 3))
            q[0] = seg[0]
            q[1] = seg[0]
        else:
            q = _resample_kernel(np.ascontiguousarray(seg[:ok + 1]), tol)
            if q.shape[0] == 0:
                return ok, tests, ok
        found, n = _any_inside_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, q, stride)
        tests += n
        if found:
            return ok, tests, -1
    return seg.shape[0], tests, -1


@njit(cache=True)
def _hulls_meeting(lo, hi, skip, q, near) -> int:  # pragma: no cover
    """How many hulls (other than ``skip``) have a box that overlaps the box of the points ``q`` (M, 3) (their
    smallest and largest coordinates, a NaN left out: it fails every box test), listed ascending in ``near``:
    a box that strictly holds one of the points has lo < that point < hi on every axis, so it meets theirs,
    and the hulls left out fail the box test of every point (exact, no margin: the points are tested as given)."""
    qlo = np.full(3, np.inf)
    qhi = np.full(3, -np.inf)
    for i in range(q.shape[0]):
        for ax in range(3):
            x = q[i, ax]
            if x < qlo[ax]:
                qlo[ax] = x
            if x > qhi[ax]:
                qhi[ax] = x
    return _boxes_meeting(lo, hi, skip, qlo, qhi, 0.0, near)


@njit(cache=True)
def _boxes_meeting(lo, hi, skip, qlo, qhi, margin, near) -> int:  # pragma: no cover
    """How many of the boxes ``lo``, ``hi`` (H, 3) (other than ``skip``) overlap the box ``qlo``..``qhi`` (3,)
    widened by ``margin`` on every side (lo < qhi + margin and hi > qlo - margin on every axis), listed
    ascending in ``near`` (``_hulls_meeting``'s and ``_hulls_near``'s filter)."""
    n = 0
    for k in range(lo.shape[0]):
        if k == skip:
            continue
        ok = True
        for ax in range(3):
            if not (lo[k, ax] < qhi[ax] + margin and hi[k, ax] > qlo[ax] - margin):
                ok = False
                break
        if ok:
            near[n] = k
            n += 1
    return n


SEGMENT_MARGIN = 1e-6
"""How far (m) past a segment's box its samples are allowed to stray by rounding in ``_segments_kernel``'s
hull filter (they stray by an ulp or so: 1e-15 m at tree scale)."""


@njit(cache=True)
def _segments_kernel(v, f, cells, flo, fhi, ftop, lo, hi, skip, start, end, counts, stride, out,
                     until_clear, ids, n_ids, prior, by) -> int:  # pragma: no cover
    tests = np.zeros(1, np.int64)
    near = np.zeros(lo.shape[0], np.int64)
    # each start's first-sample answer (0: not tried, 1: inside, 2: outside) and hull tests, by its id: a point's
    # answer and tests depend on the point alone (the hulls tried are those whose box strictly holds it, all
    # among the near hulls of any segment through it); bent_fallback tries each main vertex with 32 waypoints
    # in a row, straight_from the same 64 vertices for up to 32 centres (session 24)
    known = np.zeros(n_ids, np.int8)
    known_tests = np.zeros(n_ids, np.int64)
    known_by = np.full(n_ids, -1, np.int64)
    scratch = np.zeros(1, np.int64)
    run = 0
    for s in range(start.shape[0]):
        if until_clear and s > 0 and not out[s - 1]:
            out[s:] = True
            break
        if prior.shape[0] and prior[s] >= 0:  # a hull known to hold one of its samples (see segments_blocked)
            out[s] = True
            by[s] = prior[s]
            continue
        if s > 0 and not (start[s, 0] == start[s - 1, 0] and start[s, 1] == start[s - 1, 1]
                          and start[s, 2] == start[s - 1, 2]):
            run += 1  # no ids given: a run of equal starts shares one
        g, c = ids[s] if ids.shape[0] else run, counts[s]
        cached = c >= 2  # sample 0 is the start itself (t = 0: a NaN or infinite end makes it another point)
        for ax in range(3):
            cached = cached and start[s, ax] + 0.0 * (end[s, ax] - start[s, ax]) == start[s, ax]
        if cached and known[g] == 1:  # blocked at its start: sample 0 is tried first, whatever the near hulls
            tests[0] += known_tests[g]
            out[s] = True
            by[s] = known_by[g]
            continue
        n_near = _hulls_near(lo, hi, skip, start[s], end[s], near)
        if n_near == 0:
            continue  # no sample can lie in a hull's box: clear, and no hull tried (as sample by sample)
        inv = 1.0 / (c - 1)
        for phase in range(2):  # every stride-th sample, then the rest
            for i in range(c):
                if (i % stride == 0) != (phase == 0):
                    continue
                t = 1.0 if i == c - 1 else i * inv  # np.linspace(0, 1, c)[i], bit for bit
                x = start[s, 0] + t * (end[s, 0] - start[s, 0])
                y = start[s, 1] + t * (end[s, 1] - start[s, 1])
                z = start[s, 2] + t * (end[s, 2] - start[s, 2])
                if i > 0 or not cached:
                    by[s] = _sample_hull(v, f, cells, flo, fhi, ftop, lo, hi, near, n_near, x, y, z, tests)
                else:
                    if known[g] == 0:
                        scratch[0] = 0
                        known_by[g] = _sample_hull(v, f, cells, flo, fhi, ftop, lo, hi, near, n_near, x, y, z, scratch)
                        known[g] = 1 if known_by[g] >= 0 else 2
                        known_tests[g] = scratch[0]
                    tests[0] += known_tests[g]
                    by[s] = known_by[g]
                out[s] = by[s] >= 0
                if out[s]:
                    break
            if out[s]:
                break
    return tests[0]


@njit(cache=True)
def _sample_hull(v, f, cells, flo, fhi, ftop, lo, hi, near, n_near, x, y, z, tests) -> int:  # pragma: no cover
    """The first of the ``near`` hulls whose box strictly holds (x, y, z) and which holds it, tried in ascending
    order (``tests[0]`` counting each); -1 for none."""
    for n in range(n_near):  # ascending, as _point_inside tries them
        k = near[n]
        if not (lo[k, 0] < x < hi[k, 0] and lo[k, 1] < y < hi[k, 1] and lo[k, 2] < z < hi[k, 2]):
            continue
        tests[0] += 1
        if _hull_holds(v, f, cells, flo, fhi, ftop, k, x, y, z):
            return k
    return -1


@njit(cache=True)
def _hulls_near(lo, hi, skip, a, b, near) -> int:  # pragma: no cover
    """How many hulls (other than ``skip``) have a box that meets segment a -> b's box widened by
    ``SEGMENT_MARGIN``, listed ascending in ``near``: the only ones whose box can strictly hold one of its
    samples (a hull's box test fails for every sample of the others, so skipping them changes no answer
    and no count)."""
    return _boxes_meeting(lo, hi, skip, np.minimum(a, b), np.maximum(a, b), SEGMENT_MARGIN, near)


def warm() -> None:
    """Run every compiled loop here once on a tetrahedron, with the dtypes the refinement passes (see
    ``tetloops.warm``): the public calls first, then the loops they call inside their kernels, called
    once themselves so numba loads (or compiles) each now, not in a user's first refinement."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    pack = join_packs([pack_hull(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))])
    lo, hi = _read_only(v.min(axis=0)[None] - 1.0), _read_only(v.max(axis=0)[None] + 1.0)
    q = np.full((1, 3), 0.1)
    inside_any(pack, lo, hi, -1, q)
    any_inside(pack, lo, hi, -1, q)
    any_inside_along(pack, lo, hi, -1, v, 0.05)
    segments_blocked(pack, lo, hi, -1, q, q + 0.1, np.array([3]), until_clear=True)
    segments_blocked(pack, lo, hi, -1, q, q + 0.1, np.array([3]), prior=np.array([-1]), by=np.full(1, -1))
    first_clear_route(pack, lo, hi, -1, v, q[0], np.array([1]), np.array([3]), 0.05)
    first_clear_route(pack, lo, hi, -1, v, q[0], np.array([1]), np.array([3]), 0.05, clear=np.zeros(1, bool))
    clear_prefix(pack, lo, hi, -1, v, 0.05)
    _along_route_kernel(v, q[0], 1, 3)
    args = (pack.vertices, pack.faces, _cells(pack), pack.face_lo, pack.face_hi, pack.face_top)
    tests, near = np.zeros(1, np.int64), np.zeros(1, np.int64)
    _cell(pack.grid, 0, 0.1, 0)
    _hull_holds(*args, 0, 0.1, 0.1, 0.1)
    _point_inside(*args, lo, hi, -1, 0.1, 0.1, 0.1, tests)
    _hulls_near(lo, hi, -1, q[0], q[0] + 0.1, near)
    _hulls_meeting(lo, hi, -1, q, near)
    _boxes_meeting(lo, hi, -1, q[0], q[0], 0.0, near)
    _sample_hull(*args, lo, hi, near, 1, 0.1, 0.1, 0.1, tests)
