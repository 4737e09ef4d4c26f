"""Many closed hulls tested at once: every hull's faces with their XY boxes and top packed once into flat
arrays (``HullPack``), then points (``inside_any``) or sampled segments (``segments_blocked``) tested in one
compiled loop that stops at the first hull holding a point. Each answer is the one ``lobes.inside`` gives
hull by hull (the same ray-crossing count, ``lobes._crossings_of``), for the refinement repairs
(``clear.inside_foreign``, ``clear.blocked``) that ask it of every lobe of a tree many times over.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .lobes import _crossings_of


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


def pack_hull(vertices: np.ndarray, faces: np.ndarray) -> HullPack:
    """The ``HullPack`` of one hull (vertices (V, 3), faces (F, 3))."""
    verts = np.array(vertices, dtype=np.float64).reshape(-1, 3)  # a copy: a cache keyed by the hull's arrays holds it
    faces = np.array(faces, dtype=np.int64).reshape(-1, 3)
    corner = verts[faces]  # (F, 3 corners, 3)
    return HullPack(verts, faces, np.array([0, len(faces)], np.int64),
                    np.ascontiguousarray(corner[:, :, :2].min(axis=1)),
                    np.ascontiguousarray(corner[:, :, :2].max(axis=1)), np.ascontiguousarray(corner[:, :, 2].max(axis=1)))


def join_packs(packs: list[HullPack]) -> HullPack:
    """One ``HullPack`` of the hulls of ``packs`` (one hull each), in order."""
    if not packs:
        empty = pack_hull(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
        return empty._replace(first=np.zeros(1, np.int64))  # no hull at all, not one empty hull
    shift = np.cumsum([0] + [len(p.vertices) for p in packs[:-1]])
    return HullPack(np.concatenate([p.vertices for p in packs]),
                    np.concatenate([p.faces + s for p, s in zip(packs, shift)]),
                    np.cumsum([0] + [len(p.faces) for p in packs]).astype(np.int64),
                    np.concatenate([p.face_lo for p in packs]), np.concatenate([p.face_hi for p in packs]),
                    np.concatenate([p.face_top for p in packs]))


def inside_any(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, q: np.ndarray) -> tuple[np.ndarray, int]:
    """((M,) bool, hull tests): which ``q`` (M, 3) lie inside a hull of ``pack`` other than ``skip``, each
    hull tried only for points strictly inside its box (``lo``, ``hi`` (H, 3)) and only until one holds the
    point. The same answer as ``inside`` hull by hull; the count is of (point, hull) tests made."""
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(q), np.bool_)
    tests = _inside_any_kernel(pack.vertices, pack.faces, pack.first, pack.face_lo, pack.face_hi, pack.face_top,
                               np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64),
                               int(skip), q, out)
    return out, int(tests)


def segments_blocked(pack: HullPack, lo: np.ndarray, hi: np.ndarray, skip: int, start: np.ndarray, end: np.ndarray,
                     counts: np.ndarray, stride: int = 4) -> tuple[np.ndarray, int]:
    """((S,) bool, hull tests): which segments ``start`` -> ``end`` ((S, 3) each), sampled at ``counts``
    (S,) evenly spaced points from end to end (``np.linspace``), have a sample inside a hull of ``pack``
    other than ``skip`` (as ``inside_any``). Each segment's every ``stride``-th sample is tried first,
    and a segment stops at its first sample inside a hull: the answer of testing every sample, for the
    work of the samples up to that one (the samples are made here, only as far as they are needed)."""
    out = np.zeros(len(start), np.bool_)
    tests = _segments_kernel(pack.vertices, pack.faces, pack.first, pack.face_lo, pack.face_hi, pack.face_top,
                             np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64), int(skip),
                             np.ascontiguousarray(start, np.float64), np.ascontiguousarray(end, np.float64),
                             np.ascontiguousarray(counts, np.int64), int(stride), out)
    return out, int(tests)


@njit(cache=True)
def _point_inside(v, f, first, flo, fhi, ftop, lo, hi, skip, x, y, z, tests) -> bool:  # pragma: no cover
    """True if (x, y, z) lies inside a hull other than ``skip`` whose box strictly holds it; ``tests[0]``
    counts the hulls tried."""
    for k in range(first.shape[0] - 1):
        if k == skip or not (lo[k, 0] < x < hi[k, 0] and lo[k, 1] < y < hi[k, 1] and lo[k, 2] < z < hi[k, 2]):
            continue
        tests[0] += 1
        if _crossings_of(v, f, first[k], first[k + 1], flo, fhi, ftop, x, y, z) > 0:
            return True
    return False


@njit(cache=True)
def _inside_any_kernel(v, f, first, flo, fhi, ftop, lo, hi, skip, q, out) -> int:  # pragma: no cover
    tests = np.zeros(1, np.int64)
    for i in range(q.shape[0]):
        out[i] = _point_inside(v, f, first, flo, fhi, ftop, lo, hi, skip, q[i, 0], q[i, 1], q[i, 2], tests)
    return tests[0]


@njit(cache=True)
def _segments_kernel(v, f, first, flo, fhi, ftop, lo, hi, skip, start, end, counts, stride, out) -> int:  # pragma: no cover
    tests = np.zeros(1, np.int64)
    for s in range(start.shape[0]):
        c = counts[s]
        inv = 1.0 / (c - 1)
        for phase in range(2):  # every stride-th sample, then the rest
            for i in range(c):
                if (i % stride == 0) != (phase == 0):
                    continue
                t = 1.0 if i == c - 1 else i * inv  # np.linspace(0, 1, c)[i], bit for bit
                x = start[s, 0] + t * (end[s, 0] - start[s, 0])
                y = start[s, 1] + t * (end[s, 1] - start[s, 1])
                z = start[s, 2] + t * (end[s, 2] - start[s, 2])
                if _point_inside(v, f, first, flo, fhi, ftop, lo, hi, skip, x, y, z, tests):
                    out[s] = True
                    break
            if out[s]:
                break
    return tests[0]
