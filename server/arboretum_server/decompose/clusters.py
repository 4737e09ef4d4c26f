"""k-means for the lobes (VRTree section 3.4: "k-means of foliage points into N_l lobes"), without scikit-learn.

The same method as scikit-learn's ``KMeans(n_init=1, init="k-means++")``, which the decomposition used until
session 30: greedy k-means++ seeding (``2 + int(log k)`` candidates per centre, the one that lowers the
potential most kept; Arthur and Vassilvitskii 2007), then Lloyd's rounds until no label changes or the centres
move less than ``TOL`` of the points' mean variance in all (squared), at most ``MAX_ROUNDS``; a cluster left
empty takes the point farthest from its own centre. Not the same numbers: importing scikit-learn took 0.9-1.3 s
of every ``arboretum decompose`` here (it imports ``scipy.stats``, which parses its docstrings), against a few
milliseconds for this module's compiled rounds. One thread, sums in point order: the same centres on any machine.
"""

from __future__ import annotations

import numpy as np

from arboretum_server.jitcache import njit

TOL = 1e-4
"""Lloyd's rounds stop when the centres' total squared shift is under this fraction of the points' mean
per-axis variance (scikit-learn's default ``tol``)."""
MAX_ROUNDS = 300
"""At most this many Lloyd rounds (scikit-learn's default ``max_iter``)."""


def kmeans(points: np.ndarray, k: int, rng: np.random.Generator,
           init: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(labels (N,) int32, centres (k, 3) float64) of ``points`` (N, d) in ``min(k, N)`` clusters; ``init``
    (k, d): the starting centres instead of k-means++ (``rng`` then unused)."""
    x = np.ascontiguousarray(points, dtype=np.float64)
    if x.ndim != 2 or not len(x):
        raise ValueError(f"k-means: points must be a non-empty (N, d) array, got shape {x.shape}")
    k = int(min(k, len(x)))
    if k < 1:
        raise ValueError(f"k-means: at least one cluster is needed, got {k}")
    if init is None:
        centres = plus_plus(x, k, rng)
    else:
        centres = np.array(init, dtype=np.float64).reshape(-1, x.shape[1])
        if len(centres) != k:
            raise ValueError(f"k-means: {len(centres)} starting centres for {k} clusters")
    tol = TOL * float(np.var(x, axis=0).mean())
    labels, centres = _lloyd(x, np.ascontiguousarray(centres), tol, MAX_ROUNDS)
    return labels.astype(np.int32), centres


def plus_plus(x: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """(k, d) starting centres by greedy k-means++: the first a uniformly chosen point, each next one the
    best of ``2 + int(log k)`` points drawn with probability proportional to their squared distance to the
    nearest centre so far (the one leaving the smallest sum of those distances). The random numbers are
    drawn here, all at once; the rounds run compiled (``_plus_plus``: 40 centres of 9,000 points in
    numpy took 57 ms)."""
    trials = 2 + int(np.log(k))
    first = int(rng.integers(len(x)))
    draws = rng.random((max(k - 1, 0), trials))
    return x[_plus_plus(np.ascontiguousarray(x, dtype=np.float64), first, draws)]


@njit(cache=True, nogil=True, inline="always")
def _squared(a, b):
    """Squared distance of two points (d,)."""
    s = 0.0
    for i in range(a.shape[0]):
        t = a[i] - b[i]
        s += t * t
    return s


@njit(cache=True, nogil=True)
def _plus_plus(x, first, draws):
    """Indices (k,) of the points ``plus_plus`` starts from: ``draws`` (k - 1, trials) uniform in [0, 1)."""
    n = x.shape[0]
    k, trials = draws.shape[0] + 1, draws.shape[1]
    picked = np.zeros(k, np.int64)
    picked[0] = first
    closest = np.zeros(n)
    pot = 0.0
    for i in range(n):
        closest[i] = _squared(x[i], x[first])
        pot += closest[i]
    cum = np.zeros(n)
    cand = np.zeros((trials, n))
    for c in range(1, k):
        if pot <= 0.0:  # every point on a centre already: the rest repeat points in order
            for r in range(c, k):
                picked[r] = r % n
            break
        acc = 0.0
        for i in range(n):
            acc += closest[i]
            cum[i] = acc
        best, best_sum = -1, np.inf
        for t in range(trials):
            p = min(np.searchsorted(cum, draws[c - 1, t] * pot), n - 1)
            total = 0.0
            for i in range(n):
                s = min(_squared(x[i], x[p]), closest[i])
                cand[t, i] = s
                total += s
            if total < best_sum:
                best, best_sum = t, total
                picked[c] = p
        closest[:] = cand[best]
        pot = best_sum
    return picked


@njit(cache=True, nogil=True)
def _assign(x, centres, labels, dist):
    n, k = x.shape[0], centres.shape[0]
    changed = 0
    for i in range(n):
        best, bd = 0, np.inf
        for c in range(k):
            s = _squared(x[i], centres[c])
            if s < bd:
                best, bd = c, s
        if labels[i] != best:
            changed += 1
        labels[i] = best
        dist[i] = bd
    return changed


@njit(cache=True, nogil=True)
def _lloyd(x, centres, tol, rounds):
    n, k, dim = x.shape[0], centres.shape[0], x.shape[1]
    labels = np.full(n, -1, np.int64)
    dist = np.zeros(n)
    _assign(x, centres, labels, dist)
    for _ in range(rounds):
        sums = np.zeros((k, dim))
        count = np.zeros(k, np.int64)
        for i in range(n):
            count[labels[i]] += 1
            for a in range(dim):
                sums[labels[i], a] += x[i, a]
        new = np.zeros((k, dim))
        taken = np.zeros(n, np.bool_)
        for c in range(k):
            if count[c] > 0:
                for a in range(dim):
                    new[c, a] = sums[c, a] / count[c]
            else:  # an empty cluster takes the point farthest from its centre (not taken by another)
                far, fd = -1, -1.0
                for i in range(n):
                    if not taken[i] and dist[i] > fd:
                        far, fd = i, dist[i]
                taken[far] = True
                for a in range(dim):
                    new[c, a] = x[far, a]
        shift = 0.0
        for c in range(k):
            shift += _squared(new[c], centres[c])
        centres = new
        if _assign(x, centres, labels, dist) == 0 or shift <= tol:
            break
    return labels, centres


def warm() -> None:
    """Run the compiled rounds once (the service's warm-up, ``service.dispatch.warm_up``): their first call in a
    process loads them from numba's cache."""
    kmeans(np.eye(3), 2, np.random.default_rng(0))
