"""Branch similarity with 3D shape contexts and optimal assignment (VRTree section 3.4, after [BMP02]).

Each branch is resampled to ``n`` vertices. A vertex's shape context is the histogram of the vectors to
the branch's other vertices in log-radius (distances normalised by the branch's mean pairwise distance,
log-spaced between 1/8 and 2 as in Belongie et al.), azimuth and elevation bins. The cost of matching
two vertices is the chi-square distance of their histograms; the similarity cost of two branches is the
total cost sum_ij C[i, j] X[i, j] of the optimal assignment X (Hungarian algorithm, scipy's
linear_sum_assignment). Lower is more similar. Histograms and chi-square matrices are computed for many
branch pairs at once.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.optimize import linear_sum_assignment

from arboretum_library.geometry import resample_polyline
from arboretum_server.jitcache import njit

R_INNER, R_OUTER = 0.125, 2.0


def shape_contexts(branches: np.ndarray, bins: tuple[int, int, int] = (5, 6, 4)) -> np.ndarray:
    """Normalised histograms (B, n, nr * na * ne) of resampled branches ``branches`` (B, n, 3).

    A compiled loop (``_contexts_kernel``) gives bit for bit what ``shape_contexts_reference`` does with
    numpy on finite float64 branches of n >= 2 vertices (the tests hold the two together): a refinement
    computes the contexts of one 24-vertex path at a time, 300 times, and the 25 numpy calls of the
    reference cost 0.5 ms each time (session 26)."""
    nr, na, ne = bins
    if branches.ndim != 3 or branches.shape[1] < 2 or branches.dtype != np.float64 or min(bins) < 1:
        return shape_contexts_reference(branches, bins)
    b, n, _ = branches.shape
    out = np.zeros((b, n, nr * na * ne))
    ok = _contexts_kernel(np.ascontiguousarray(branches), radius_edges(nr), na, ne, out)
    return out if ok else shape_contexts_reference(branches, bins)


@functools.lru_cache(maxsize=16)
def radius_edges(nr: int) -> np.ndarray:
    """The ``nr`` + 1 log-spaced radius bin edges from ``R_INNER`` to ``R_OUTER`` (read-only; ``np.geomspace``
    costs more than a shape context's compiled loop, so it is computed once per bin count)."""
    edges = np.geomspace(R_INNER, R_OUTER, nr + 1)
    edges.flags.writeable = False
    return edges


def shape_contexts_reference(branches: np.ndarray, bins: tuple[int, int, int] = (5, 6, 4)) -> np.ndarray:
    """``shape_contexts`` in numpy (the slow reference)."""
    nr, na, ne = bins
    b, n, _ = branches.shape
    v = branches[:, None, :, :] - branches[:, :, None, :]  # (B, n, n, 3): from vertex i to j
    r = np.linalg.norm(v, axis=3)
    off = ~np.eye(n, dtype=bool)[None]
    mean = np.maximum((r * off).sum(axis=(1, 2)) / (n * (n - 1)), 1e-12)
    rn = r / mean[:, None, None]
    edges = np.geomspace(R_INNER, R_OUTER, nr + 1)
    ri = np.clip(np.searchsorted(edges, rn) - 1, 0, nr - 1)
    az = np.arctan2(v[..., 1], v[..., 0])
    ai = np.clip(((az + np.pi) / (2 * np.pi) * na).astype(int), 0, na - 1)
    el = np.arcsin(np.clip(v[..., 2] / np.maximum(r, 1e-12), -1.0, 1.0))
    ei = np.clip(((el + np.pi / 2) / np.pi * ne).astype(int), 0, ne - 1)
    flat = (ri * na + ai) * ne + ei
    k = nr * na * ne
    bi, ii, _ = np.nonzero(np.broadcast_to(off, (b, n, n)))
    # whole counts, so the same floats as adding 1.0 per vector (np.add.at, before session 15), 5x faster
    hist = np.bincount((bi * n + ii) * k + flat[off.repeat(b, axis=0)], minlength=b * n * k).astype(np.float64)
    return hist.reshape(b, n, k) / (n - 1)


@njit(cache=True)
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover - numba
    """numpy's ``pairwise_sum`` (loops_utils.h) of ``a[lo:lo + n]`` for n <= ``PAIRWISE_BLOCK``: under 8
    one by one, else in eight running sums combined ((0 + 1) + (2 + 3)) + ((4 + 5) + (6 + 7)) and the
    last n % 8 one by one."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    acc = np.zeros(8)
    for c in range(8):
        acc[c] = a[lo + c]
    i = 8
    while i < n - n % 8:
        for c in range(8):
            acc[c] += a[lo + i + c]
        i += 8
    res = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover - numba
    """numpy's ``pairwise_sum`` of ``a[lo:lo + n]``: a block (``_block_sum``) up to ``PAIRWISE_BLOCK``,
    larger ranges as the sum of their halves (the first rounded down to a multiple of 8), walked with an
    explicit stack (numba's cache does not keep recursive functions)."""
    los, ns, stage = np.zeros(64, np.int64), np.zeros(64, np.int64), np.zeros(64, np.int64)
    vals = np.zeros(64)
    top, nv = 0, 0
    los[0], ns[0], stage[0] = lo, n, 0
    while top >= 0:
        m = ns[top]
        half = m // 2 - (m // 2) % 8
        if m <= 128:
            vals[nv] = _block_sum(a, los[top], m)
            nv += 1
            top -= 1
        elif stage[top] == 0:
            stage[top] = 1
            los[top + 1], ns[top + 1], stage[top + 1] = los[top], half, 0
            top += 1
        elif stage[top] == 1:
            stage[top] = 2
            los[top + 1], ns[top + 1], stage[top + 1] = los[top] + half, m - half, 0
            top += 1
        else:
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
    return vals[0]


@njit(cache=True)
def _contexts_kernel(br: np.ndarray, edges: np.ndarray, na: int, ne: int, out: np.ndarray) -> bool:  # pragma: no cover - numba
    """``shape_contexts_reference`` into ``out`` (B, n, k), zeros on entry; False (``out`` unfinished) on a
    non-finite vertex. The same float operations: each vector's norm as numpy's ((x^2 + y^2) + z^2), the
    mean distance as numpy's pairwise sum of the n * n distances (the diagonal's zeros included) divided
    by n (n - 1), the radius bin as ``np.searchsorted`` (left) on ``edges``, azimuth and elevation bins
    from ``np.arctan2`` and ``np.arcsin`` (the same libm calls as numpy's loops; the tests compare), each
    count divided by n - 1."""
    b, n = br.shape[0], br.shape[1]
    nr = edges.shape[0] - 1
    r = np.zeros(n * n)
    for q in range(b):
        for i in range(n):
            for j in range(n):
                dx, dy, dz = br[q, j, 0] - br[q, i, 0], br[q, j, 1] - br[q, i, 1], br[q, j, 2] - br[q, i, 2]
                r[i * n + j] = np.sqrt(dx * dx + dy * dy + dz * dz) if i != j else 0.0
                if not np.isfinite(r[i * n + j]):
                    return False
        mean = _pairwise_sum(r, 0, n * n) / (n * (n - 1))
        mean = mean if mean > 1e-12 else 1e-12
        for i in range(n):
            for j in range(n):
                if i == j:
                    continue
                dx, dy, dz = br[q, j, 0] - br[q, i, 0], br[q, j, 1] - br[q, i, 1], br[q, j, 2] - br[q, i, 2]
                rij = r[i * n + j]
                rn = rij / mean
                ri = 0
                while ri <= nr and edges[ri] < rn:
                    ri += 1
                ri = min(max(ri - 1, 0), nr - 1)
                ai = int((np.arctan2(dy, dx) + np.pi) / (2 * np.pi) * na)
                ai = min(max(ai, 0), na - 1)
                z = dz / (rij if rij > 1e-12 else 1e-12)
                el = np.arcsin(min(max(z, -1.0), 1.0))
                ei = int((el + np.pi / 2) / np.pi * ne)
                ei = min(max(ei, 0), ne - 1)
                out[q, i, (ri * na + ai) * ne + ei] += 1.0
        for i in range(n):
            for c in range(out.shape[2]):
                out[q, i, c] = out[q, i, c] / (n - 1)
    return True


PAIRWISE_BLOCK = 128
"""numpy sums a float64 block of up to this many in eight running sums (``pairwise_sum`` in its
loops_utils.h), larger ones by halves; ``chi_square`` compiles the first case only."""


def chi_square(h1: np.ndarray, h2: np.ndarray) -> np.ndarray:
    """Chi-square cost matrix (n1, n2) between normalised histograms h1 (n1, k) and h2 (n2, k) (>= 0).

    With both histograms summing to 1, 0.5 sum (a - b)^2 / (a + b) = 1 - 2 sum ab / (a + b).
    For k <= ``PAIRWISE_BLOCK`` (the default bins give 120) a compiled loop computes only the terms where
    both bins are filled (a shape context fills at most n - 1 of its k bins) and sums them in numpy's
    order, bit for bit what ``chi_square_reference`` gives on C-ordered rows, which every caller passes
    (on a Fortran-ordered array numpy sums in another order; the tests hold the two together): 0.007 ms a
    pair of 24-vertex branches against numpy's 0.13 ms, about 100 pairs an "around" insert (session 15).
    """
    h1 = np.ascontiguousarray(h1, dtype=np.float64)
    h2 = np.ascontiguousarray(h2, dtype=np.float64)
    if h1.shape[1] > PAIRWISE_BLOCK:
        return chi_square_reference(h1, h2)
    out = np.zeros((len(h1), len(h2)))
    _chi_square_kernel(h1, h2, out)
    return out


def chi_square_reference(h1: np.ndarray, h2: np.ndarray) -> np.ndarray:
    """``chi_square`` in numpy, over every bin (the slow reference)."""
    a, b = h1[:, None, :], h2[None, :, :]
    s = a + b
    return 1.0 - 2.0 * (a * b / (s + (s == 0))).sum(axis=2)


@njit(cache=True)
def _chi_square_kernel(h1: np.ndarray, h2: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - numba
    """``chi_square_reference`` for k <= ``PAIRWISE_BLOCK`` bins. numpy sums the k terms of a pair in eight
    running sums (term c into sum c % 8, in order of c; for k < 8 one sum), combines them as ((0 + 1) +
    (2 + 3)) + ((4 + 5) + (6 + 7)) and adds the last k % 8 terms one by one. A term is 0.0 exactly unless
    both bins are filled, and adding 0.0 changes no sum (every term is >= 0), so only the filled bins of
    ``h1``'s row are visited, into the same running sums in the same order."""
    k = h1.shape[1]
    block = k - k % 8 if k >= 8 else 0
    filled = np.zeros(k, np.int64)
    acc = np.zeros(8)
    for i in range(h1.shape[0]):
        m = 0
        for c in range(k):
            if h1[i, c] != 0.0:
                filled[m] = c
                m += 1
        for j in range(h2.shape[0]):
            acc[:] = 0.0
            q = 0
            while q < m and filled[q] < block:
                c = filled[q]
                a, b = h1[i, c], h2[j, c]
                if b != 0.0:
                    acc[c % 8] += a * b / (a + b)
                q += 1
            res = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
            while q < m:
                c = filled[q]
                a, b = h1[i, c], h2[j, c]
                if b != 0.0:
                    res += a * b / (a + b)
                q += 1
            out[i, j] = 1.0 - 2.0 * res


def assignment_cost(h1: np.ndarray, h2: np.ndarray) -> float:
    """Total cost sum_ij C[i, j] X[i, j] of the optimal assignment between two branches' histograms."""
    c = chi_square(h1, h2)
    r, k = linear_sum_assignment(c)
    return float(c[r, k].sum())


def assignment_costs(h1: np.ndarray, h2s: np.ndarray, which: np.ndarray) -> list[float]:
    """``assignment_cost(h1, h2s[w])`` for each w in ``which``: the chi-square matrices of all of them from
    one compiled call (``chi_squares``), then one optimal assignment each."""
    out = []
    for c in chi_squares(h1, h2s, which):
        r, k = linear_sum_assignment(c)
        out.append(float(c[r, k].sum()))
    return out


def chi_squares(h1: np.ndarray, h2s: np.ndarray, which: np.ndarray) -> np.ndarray:
    """(W, n1, n2): ``chi_square(h1, h2s[w])`` for each w in ``which`` (``h2s`` (M, n2, k)), bit for bit.

    ``_chi_squares_kernel`` visits the terms bin by bin, only where both histograms are filled (a
    24-vertex branch fills about 3 of its 120 bins a vertex), adding each into the pair's running sum c % 8
    in increasing c as ``_chi_square_kernel`` does; one call for the 2-8 main branches ``merge.choose_parent``
    compares a path with (session 26: 14 -> ~4 us a pair of 24-vertex branches, plus one dispatch
    instead of one a branch)."""
    h1 = np.ascontiguousarray(h1, dtype=np.float64)
    which = np.asarray(which, dtype=np.int64)
    if h1.shape[1] > PAIRWISE_BLOCK or h2s.ndim != 3 or h2s.dtype != np.float64:
        return np.stack([chi_square(h1, h2s[w]) for w in which]) if len(which) else np.zeros((0, len(h1), h2s.shape[1]))
    out = np.zeros((len(which), len(h1), h2s.shape[1]))
    _chi_squares_kernel(h1, np.ascontiguousarray(h2s), which, out)
    return out


@njit(cache=True)
def _add_bin(h1: np.ndarray, h2: np.ndarray, rows: np.ndarray, count: np.ndarray, c: int,
             dest: np.ndarray) -> None:  # pragma: no cover - numba
    """Bin ``c``'s chi-square terms a b / (a + b) of the ``count[c]`` rows of ``h1`` filled there (``rows``)
    against the rows of ``h2`` filled there, each added into ``dest[i, j]`` ((n1, n2): a running sum)."""
    if count[c] == 0:
        return
    for j in range(h2.shape[0]):
        b = h2[j, c]
        if b != 0.0:
            for t in range(count[c]):
                i = rows[c, t]
                a = h1[i, c]
                dest[i, j] += a * b / (a + b)


@njit(cache=True)
def _chi_squares_kernel(h1: np.ndarray, h2s: np.ndarray, which: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - numba
    """``chi_squares``' loop: for each bin c below the last k % 8 (numpy's eight running sums), the rows of
    ``h1`` filled there against the rows of ``h2s[w]`` filled there, each term a b / (a + b) added to the
    pair's running sum c % 8; the sums combined ((0 + 1) + (2 + 3)) + ((4 + 5) + (6 + 7)), then the tail
    bins' terms added one by one in order of c (``_chi_square_kernel``'s sums, visited bin-major)."""
    n1, k = h1.shape
    n2 = h2s.shape[1]
    block = k - k % 8 if k >= 8 else 0
    count = np.zeros(k, np.int64)
    rows = np.zeros((k, max(n1, 1)), np.int64)
    for i in range(n1):
        for c in range(k):
            if h1[i, c] != 0.0:
                rows[c, count[c]] = i
                count[c] += 1
    acc = np.zeros((n1, n2, 8))
    for w in range(len(which)):
        h2 = h2s[which[w]]
        acc[:] = 0.0
        for c in range(block):
            _add_bin(h1, h2, rows, count, c, acc[:, :, c % 8])
        for i in range(n1):
            for j in range(n2):
                out[w, i, j] = ((acc[i, j, 0] + acc[i, j, 1]) + (acc[i, j, 2] + acc[i, j, 3])) + \
                    ((acc[i, j, 4] + acc[i, j, 5]) + (acc[i, j, 6] + acc[i, j, 7]))
        for c in range(block, k):
            _add_bin(h1, h2, rows, count, c, out[w])
        for i in range(n1):
            for j in range(n2):
                out[w, i, j] = 1.0 - 2.0 * out[w, i, j]


def similarity_costs(a: np.ndarray, b: np.ndarray, bins: tuple[int, int, int] = (5, 6, 4)) -> np.ndarray:
    """Optimal-assignment costs (A, B) between resampled branches a (A, n, 3) and b (B, n, 3)."""
    ha, hb = shape_contexts(a, bins), shape_contexts(b, bins)
    return np.array([[assignment_cost(x, y) for y in hb] for x in ha]).reshape(len(ha), len(hb))


def resample_all(polylines: list[np.ndarray], n: int) -> np.ndarray:
    """(B, n, 3) array of each polyline in ``polylines`` resampled to ``n`` vertices (``resample_polyline``).

    One compiled loop over all of them (``_resample_n_kernel``) gives bit for bit what
    ``resample_all_reference`` does (the tests hold the two together); the reference takes it back for
    anything but finite (N >= 1, 3) polylines and n >= 1."""
    if not polylines:
        return np.zeros((0, n, 3))
    lens = np.array([len(p) for p in polylines], np.int64)
    if n < 1 or lens.min() < 1 or any(np.ndim(p) != 2 or np.shape(p)[1] != 3 for p in polylines):
        return resample_all_reference(polylines, n)
    out = np.zeros((len(polylines), n, 3))
    flat = np.concatenate(polylines).astype(np.float64, copy=False)
    ok = _resample_n_kernel(np.ascontiguousarray(flat), np.r_[0, np.cumsum(lens)[:-1]], lens, out)
    return out if ok else resample_all_reference(polylines, n)


def resample_all_reference(polylines: list[np.ndarray], n: int) -> np.ndarray:
    """``resample_all`` with numpy, one ``resample_polyline`` per polyline (the slow reference)."""
    return np.stack([resample_polyline(p, n) for p in polylines]) if polylines else np.zeros((0, n, 3))


@njit(cache=True)
def arc_lengths(pts: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """(M,) the running sum of the lengths ((dx^2 + dy^2) + dz^2 under the root, ``np.linalg.norm``'s
    order) of the steps of the polyline ``pts`` (M >= 1, 3), 0 first."""
    m = pts.shape[0]
    s = np.zeros(m)
    acc = 0.0
    for i in range(1, m):
        dx, dy, dz = pts[i, 0] - pts[i - 1, 0], pts[i, 1] - pts[i - 1, 1], pts[i, 2] - pts[i - 1, 2]
        acc += np.sqrt(dx * dx + dy * dy + dz * dz)
        s[i] = acc
    return s


@njit(cache=True)
def _resample_n_kernel(flat: np.ndarray, starts: np.ndarray, lens: np.ndarray, out: np.ndarray) -> bool:  # pragma: no cover - numba
    """``resample_polyline`` of each polyline ``flat[starts[b]:starts[b] + lens[b]]`` to ``out[b]`` (n, 3); False
    on a non-finite length. The same float operations as ``merge._resample_kernel``: norms of the
    differences and their running sum (``polyline_lengths``), the first vertex repeated when that length is
    not positive, ``np.linspace``'s i * (length / (n - 1)) with the end set to the length, ``np.interp``'s
    interval search, slopes, exact hits and nan fallbacks."""
    n = out.shape[1]
    for b in range(len(lens)):
        pts = flat[starts[b]:starts[b] + lens[b]]
        m = pts.shape[0]
        s = arc_lengths(pts)
        length = s[m - 1]
        if not np.isfinite(length):
            return False
        if not length > 0.0:
            for i in range(n):
                for k in range(3):
                    out[b, i, k] = pts[0, k]
            continue
        delta = length / (n - 1) if n > 1 else 0.0
        j = 0
        for i in range(n):
            if n == 1:
                x = 0.0
            else:
                x = length if i == n - 1 else (i * delta if delta != 0.0 else (i / (n - 1)) * length)
            while j + 1 < m and x >= s[j + 1]:  # x grows: the last j with s[j] <= x
                j += 1
            for k in range(3):
                if j == m - 1 or s[j] == x:
                    out[b, i, k] = pts[j, k]
                else:
                    slope = (pts[j + 1, k] - pts[j, k]) / (s[j + 1] - s[j])
                    out[b, i, k] = slope * (x - s[j]) + pts[j, k]
                    if np.isnan(out[b, i, k]):  # np.interp tries the other end, then a flat interval's value
                        out[b, i, k] = slope * (x - s[j + 1]) + pts[j + 1, k]
                        if np.isnan(out[b, i, k]) and pts[j, k] == pts[j + 1, k]:
                            out[b, i, k] = pts[j, k]
    return True


def warm() -> None:
    """Run the compiled loops once: ``chi_square``'s, ``chi_squares``', ``shape_contexts``' and
    ``resample_all``'s (see ``tetloops.warm``)."""
    chi_square(np.eye(2, 120), np.eye(2, 120))
    chi_squares(np.eye(2, 120), np.eye(2, 120)[None], np.zeros(1, np.int64))
    shape_contexts(resample_all([np.array([[0.0, 0, 0], [0, 0, 1], [0, 1, 1]])], 4))
    _block_sum(np.ones(3), 0, 3)  # the loops the kernels call, compiled on their own too
    _add_bin(np.eye(2, 120), np.eye(2, 120), np.zeros((120, 2), np.int64), np.zeros(120, np.int64), 0,
             np.zeros((2, 2)))
    arc_lengths(np.zeros((2, 3)))
    _pairwise_sum(np.ones(3), 0, 3)
