"""Keeping a secondary branch out of the lobes it does not feed: the inside tests, and the two repairs that
replace a routed branch which still enters a foreign lobe (VRTree has neither; ours, see secondary.py):

- ``straight_fallback``: a straight segment from the nearest main-branch vertex whose segment to the
  lobe centre stays clear;
- ``bent_fallback``: a two-piece branch, main vertex -> one of the lobe's own points -> lobe centre
  (every (n // ``waypoints``)-th of its n points, 32-63 of them, whose segment to the centre is
  clear).
"""

from __future__ import annotations

import numpy as np

from .lobes import inside
from .merge import BranchSet, resample_step
from .state import LobeState


def boxes(lobes: list[LobeState]) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes (lo (L, 3), hi (L, 3)) of the lobes' hulls."""
    return (np.array([lb.hull_vertices.min(axis=0) for lb in lobes]),
            np.array([lb.hull_vertices.max(axis=0) for lb in lobes]))


def inside_foreign(lobes: list[LobeState], j: int, q: np.ndarray,
                   box: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(M,) bool: which of the points ``q`` (M, 3) lie inside a lobe other than ``j``."""
    lo, hi = box if box is not None else boxes(lobes)
    inbox = ((q[None] > lo[:, None]) & (q[None] < hi[:, None])).all(axis=2)  # (L, M)
    inbox[j] = False
    out = np.zeros(len(q), bool)
    for k in np.flatnonzero(inbox.any(axis=1)):
        sel = np.flatnonzero(inbox[k] & ~out)
        if len(sel):
            lb = lobes[k]
            out[sel] = inside(lb.hull_vertices, lb.hull_faces, q[sel])
    return out


def foreign(lobes: list[LobeState], j: int, seg: np.ndarray, tol: float,
            box: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """True if a vertex of ``seg`` (resampled every ``tol``) lies inside a lobe other than ``j``."""
    return bool(inside_foreign(lobes, j, resample_step(seg, tol), box).any())


def main_vertices(mains: BranchSet) -> tuple[np.ndarray, np.ndarray]:
    """Every main-branch vertex (V, 3) and its (segment, vertex index) (V, 2)."""
    owner = np.concatenate([np.stack([np.full(len(s), b), np.arange(len(s))], 1) for b, s in enumerate(mains.segments)])
    return np.concatenate(mains.segments), owner


def straight_fallback(lobes: list[LobeState], j: int, mains: BranchSet, tries: int = 64,
                      step: float = 0.005, batch: int = 8) -> tuple[np.ndarray, int, int] | None:
    """A straight secondary branch for lobe ``j`` from the nearest main-branch vertex whose segment to the
    lobe centre stays out of foreign lobes (candidates tested ``batch`` at a time, nearest first), or None."""
    centre = lobes[j].centre
    verts, owner = main_vertices(mains)
    dist = np.linalg.norm(verts - centre, axis=1)
    order = np.array([i for i in np.argsort(dist)[:tries] if dist[i] > 1e-9], dtype=int)
    box = boxes(lobes)
    for start in range(0, len(order), batch):
        cand = order[start : start + batch]
        q, which = _segment_samples(verts[cand], np.broadcast_to(centre, (len(cand), 3)), step)
        bad = _blocked(lobes, j, q, which, len(cand), box)
        if not bad.all():
            i = int(cand[int(np.argmin(bad))])
            m = max(2, int(np.ceil(dist[i] / 0.01)) + 1)
            seg = verts[i] + np.linspace(0.0, 1.0, m)[:, None] * (centre - verts[i])
            return seg, int(owner[i, 0]), int(owner[i, 1])
    return None


def _blocked(lobes: list[LobeState], j: int, q: np.ndarray, which: np.ndarray, n: int,
             box: tuple[np.ndarray, np.ndarray], stride: int = 4) -> np.ndarray:
    """(n,) bool: segments (samples ``q`` (M, 3) of segment ``which`` (M,)) with a sample inside a lobe
    other than ``j``. Every ``stride``-th sample first: most blocked segments show it there, and only
    the segments still clear are tested at every sample (the same answer, a fraction of the cost)."""
    coarse = np.arange(len(q)) % stride == 0
    bad = np.bincount(which[coarse], weights=inside_foreign(lobes, j, q[coarse], box), minlength=n) > 0
    rest = ~coarse & ~bad[which]
    return bad | (np.bincount(which[rest], weights=inside_foreign(lobes, j, q[rest], box), minlength=n) > 0)


def _segment_samples(a: np.ndarray, b: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ~``step`` along the segments a[i] -> b[i] ((S, 3) each) and the segment of each."""
    counts = np.maximum(2, np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(int) + 1)
    which = np.repeat(np.arange(len(a)), counts)
    first = np.cumsum(counts) - counts
    i = np.arange(len(which)) - first[which]
    t = i * (1.0 / (counts - 1))[which]  # np.linspace(0, 1, count) for each segment, bit for bit
    t[first + counts - 1] = 1.0
    t = t[:, None]
    return a[which] + t * (b[which] - a[which]), which


def bent_fallback(lobes: list[LobeState], j: int, mains: BranchSet, pts: np.ndarray, waypoints: int = 32,
                  tries: int = 48, batch: int = 2, step: float = 0.005) -> tuple[np.ndarray, int, int] | None:
    """A two-piece secondary branch for lobe ``j``: main-branch vertex -> one of the lobe's own points ->
    lobe centre, both pieces clear of foreign lobes, through every (n // ``waypoints``)-th of the lobe's
    n points whose segment to the centre is clear. The ``tries`` main vertices nearest the centre that
    lie outside every foreign lobe are tested ``batch`` at a time, nearest first; the first batch with a
    clear route gives the shortest one. None if none has one. For lobes that no straight segment reaches (lobes around a pine's trunk)."""
    centre, box = lobes[j].centre, boxes(lobes)
    members = pts[lobes[j].members]
    w = members[:: max(1, len(members) // waypoints)]
    q, which = _segment_samples(w, np.broadcast_to(centre, w.shape), step)
    w = w[~_blocked(lobes, j, q, which, len(w), box)]
    if not len(w):
        return None
    verts, owner = main_vertices(mains)
    order = np.argsort(np.linalg.norm(verts - centre, axis=1))
    order = order[~inside_foreign(lobes, j, verts[order], box)][:tries]  # a start in a foreign lobe fails
    for start in range(0, len(order), batch):
        v = np.repeat(order[start : start + batch], len(w))  # every (vertex, waypoint) pair of the batch
        ww = np.tile(w, (len(v) // len(w), 1))
        q, which = _segment_samples(verts[v], ww, step)
        bad = _blocked(lobes, j, q, which, len(v), box)
        if bad.all():
            continue
        length = np.where(bad, np.inf, np.linalg.norm(ww - verts[v], axis=1) + np.linalg.norm(ww - centre, axis=1))
        k = int(np.argmin(length))
        a, b = verts[v[k]], ww[k]
        seg = np.vstack([resample_step(np.stack([a, b]), 0.01), resample_step(np.stack([b, centre]), 0.01)[1:]])
        return seg, int(owner[v[k], 0]), int(owner[v[k], 1])
    return None
