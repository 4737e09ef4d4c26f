"""Spatial helpers for raw scans, numpy only: up axis, trunk base, even thinning, point spacing.

Split out of ``pointio`` (which re-exports them) so that file stays about reading and writing.
"""

from __future__ import annotations

import numpy as np


def guess_up_axis(points: np.ndarray) -> tuple[str, float]:
    """Guess whether a tree stands along +Z or +Y; returns ('z' | 'y', confidence in [0.5, 1)).

    For each candidate axis, an upright score: log(elongation) - 0.75 log(trunk / width), where
    elongation is the robust extent along the axis (0.5-99.5 percentile) over the crown width across it
    (2 x the 95th percentile distance from the median), and trunk is the same width measured in the lowest
    10% of the extent; an axis whose footprint is a line (thinner than ``SLAB_RATIO`` of its length: a
    flat cloud stood on its edge) loses 4 log(ratio / SLAB_RATIO). Trees are taller than wide, narrow at the
    foot and round in plan. X is never a candidate; a tie goes to Z. The confidence is a logistic of the score difference. See docs/scan-input.md for limits.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) > 50_000:
        pts = pts[np.random.default_rng(0).choice(len(pts), 50_000, replace=False)]
    s_z, s_y = _upright_score(pts, 2), _upright_score(pts, 1)
    confidence = float(1.0 / (1.0 + np.exp(-2.0 * min(abs(s_z - s_y), 20.0))))
    return ("y" if s_y > s_z else "z"), confidence


SLAB_RATIO = 0.1
"""Footprint thinner than this fraction of its length: the cloud lies on its side along that axis."""


def _upright_score(pts: np.ndarray, axis: int) -> float:
    h = pts[:, axis]
    across = np.delete(pts, axis, axis=1)
    eps = 1e-9 * float(np.ptp(pts, axis=0).max())
    lo, hi = np.percentile(h, [0.5, 99.5])
    width = 2.0 * _spread(across)
    trunk = 2.0 * _spread(across[h <= lo + 0.1 * (hi - lo)])
    elongation = max(hi - lo, eps) / max(width, eps)
    narrow = min(max(trunk / max(width, eps), 0.01), 100.0)
    return float(np.log(elongation) - 0.75 * np.log(narrow) + 4.0 * np.log(_footprint(across, eps)))


def _footprint(across: np.ndarray, eps: float) -> float:
    """min(1, (thin / long extent of the footprint) / SLAB_RATIO): below 1 for a slab standing on its edge
    (a ground disc read with the wrong up axis), whose footprint is a line; a crown's is round."""
    ext = np.percentile(across, 99.5, axis=0) - np.percentile(across, 0.5, axis=0)
    return min(1.0, max(float(ext.min()), eps) / max(float(ext.max()), eps) / SLAB_RATIO)


def _spread(xy: np.ndarray, q: float = 95.0) -> float:
    """The ``q``-th percentile distance of 2D points (M, 2) from their median."""
    return (
        float(np.percentile(np.linalg.norm(xy - np.median(xy, axis=0), axis=1), q))
        if len(xy)
        else 0.0
    )


def trunk_base(points: np.ndarray, slab_fraction: float = 0.02, min_points: int = 20) -> np.ndarray:
    """The trunk base (3,): median X and Y of the lowest slab of points, and the lowest Z.

    The slab holds the points within ``slab_fraction`` of the height above the lowest point, or the
    ``min_points`` lowest points when it holds fewer (a stray low point cannot move the base much).
    """
    pts = np.asarray(points, dtype=np.float64)
    z = pts[:, 2]
    slab = pts[z <= z.min() + slab_fraction * np.ptp(z)]
    if len(slab) < min_points:
        slab = pts[np.argsort(z, kind="stable")[: min(min_points, len(pts))]]
    x, y = np.median(slab[:, :2], axis=0)
    return np.array([x, y, z.min()])


def _voxel_keys(points: np.ndarray, size: float, pad: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """An int64 key (N,) per point for cubic voxels of ``size``, and the key strides (3,)."""
    ijk = np.floor((points - points.min(axis=0)) / size).astype(np.int64) + pad
    dims = ijk.max(axis=0) + 1 + pad
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    return ijk @ strides, strides


def even_sample_indices(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices (n,) int64, ascending, of ``n`` points spread evenly over ``points`` (N, 3).

    Voxel grid then random fill: the voxel size is found by bisection so that about ``n`` voxels are
    occupied (on a random subset of 200,000 points for larger clouds); points are ranked at random within their voxel, and the ``n`` points of lowest rank are
    kept (ties at random). Every voxel so keeps one point before any voxel keeps two, and dense parts of
    a scan are thinned more than sparse ones. Same ``rng`` state, same result.
    """
    pts = np.asarray(points, dtype=np.float64)
    count = len(pts)
    if n >= count:
        return np.arange(count)
    probe = (
        pts
        if count <= max(200_000, 4 * n)
        else pts[rng.choice(count, max(200_000, 4 * n), replace=False)]
    )
    keys, _ = _voxel_keys(pts, _voxel_size_for(probe, n))
    order = _shuffled_argsort(keys, rng)
    sorted_keys = keys[order]
    first = np.concatenate([[True], sorted_keys[1:] != sorted_keys[:-1]])
    rank = np.zeros(count, dtype=np.int64)
    rank[order] = np.arange(count) - np.maximum.accumulate(np.where(first, np.arange(count), 0))
    return np.sort(_shuffled_argsort(rank, rng)[:n])


def _shuffled_argsort(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices sorting ``values``, equal values in random order."""
    perm = rng.permutation(len(values))
    return perm[np.argsort(values[perm], kind="stable")]


def _voxel_size_for(pts: np.ndarray, n: int, steps: int = 10) -> float:
    """A voxel size at which about ``n`` (at most ``n`` where possible) voxels of ``pts`` are occupied."""
    extent = float(np.ptp(pts, axis=0).max())
    lo, hi = np.log2(extent) - 20.0, np.log2(extent) + 0.01
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if np.unique(_voxel_keys(pts, 2.0**mid)[0]).size > n:
            lo = mid
        else:
            hi = mid
    return float(2.0**hi)


def median_spacing(points: np.ndarray, rng: np.random.Generator, samples: int = 2000) -> float:
    """Median nearest-neighbour distance (metres) over up to ``samples`` random points of ``points``.

    Exact for the sampled points: neighbours are searched in the 27 cells of a voxel grid of cell size
    h, and a point whose nearest neighbour is not within h is searched again with 2h.
    """
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 2:
        return 0.0
    query = rng.choice(len(pts), min(samples, len(pts)), replace=False)
    h = max(float(np.ptp(pts, axis=0).max()) / np.sqrt(len(pts)), 1e-12)
    dist = np.full(len(query), np.inf)
    todo = np.arange(len(query))
    while todo.size:
        dist[todo] = _nearest_within(pts, query[todo], h)
        todo = todo[~(dist[todo] <= h)]
        h *= 2.0
    return float(np.median(dist))


def _nearest_within(pts: np.ndarray, query: np.ndarray, h: float, chunk: int = 128) -> np.ndarray:
    """Distance (Q,) from each ``pts[query]`` to its nearest other point among the 27 cells around it."""
    keys, strides = _voxel_keys(pts, h, pad=1)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    offsets = (
        np.stack(np.meshgrid(*[[-1, 0, 1]] * 3, indexing="ij"), axis=-1).reshape(-1, 3) @ strides
    )
    out = np.full(len(query), np.inf)
    for s in range(0, len(query), chunk):
        q = query[s : s + chunk]
        cells = (keys[q][:, None] + offsets[None]).ravel()
        left = np.searchsorted(sorted_keys, cells, "left")
        lengths = np.searchsorted(sorted_keys, cells, "right") - left
        owner = np.repeat(np.arange(cells.size), lengths)
        within = np.arange(owner.size) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        cand = order[left[owner] + within]
        row = owner // len(offsets)
        d = np.linalg.norm(pts[cand] - pts[q[row]], axis=1)
        d[cand == q[row]] = np.inf
        best = np.full(len(q), np.inf)
        np.minimum.at(best, row, d)
        out[s : s + chunk] = best
    return out
