"""Reference lobe edits on an HBL (numpy), used by ``FakeSession``; the server has its own.

Remove a lobe (its points stay in the cloud), insert a lobe from selected points (attached to the
nearest branch), merge lobes (union of points, hull around them), split a lobe by strokes (each point
goes to the nearest stroke; one lobe per stroke). Hulls are octahedra enclosing the points.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.model import HBL, Lobe

from .demo import octa_lobe


def _hull_lobe(points: np.ndarray, branch: int) -> Lobe:
    centre = points.mean(axis=0)
    radius = float(np.abs(points - centre).sum(axis=1).max()) * 1.05 + 1e-3  # L1 ball = octahedron
    return octa_lobe(points, centre, radius, branch)


def _check(hbl: HBL, lobes: Sequence[int]) -> None:
    for j in lobes:
        if not 0 <= j < len(hbl.lobes):
            raise InputError(f"lobe {j}: out of range (the draft has {len(hbl.lobes)} lobes)")


def remove_lobe(hbl: HBL, lobe: int) -> HBL:
    _check(hbl, [lobe])
    return dataclasses.replace(hbl, lobes=tuple(lb for j, lb in enumerate(hbl.lobes) if j != lobe))


def insert_lobe(hbl: HBL, indices: np.ndarray) -> HBL:
    idx = np.unique(np.asarray(indices, np.int64))
    if len(idx) < 4 or idx.min() < 0 or idx.max() >= len(hbl.points):
        raise InputError(f"insert lobe: select at least 4 points of the cloud (got {len(idx)})")
    pts = hbl.points[idx]
    tips = np.array([b.points[-1] for b in hbl.branches])
    branch = int(np.linalg.norm(tips - pts.mean(axis=0), axis=1).argmin())
    return dataclasses.replace(hbl, lobes=(*hbl.lobes, _hull_lobe(pts, branch)))


def merge_lobes(hbl: HBL, lobes: Sequence[int]) -> HBL:
    lobes = sorted(set(lobes))
    if len(lobes) < 2:
        raise InputError("merge lobes: select two or more lobes")
    _check(hbl, lobes)
    pts = np.concatenate([hbl.lobes[j].points if len(hbl.lobes[j].points) else hbl.lobes[j].hull_vertices
                          for j in lobes])
    merged = _hull_lobe(pts, hbl.lobes[lobes[0]].branch)
    keep = [lb for j, lb in enumerate(hbl.lobes) if j not in lobes]
    return dataclasses.replace(hbl, lobes=(*keep, merged))


def split_lobe(hbl: HBL, lobe: int, strokes: Sequence[np.ndarray]) -> HBL:
    _check(hbl, [lobe])
    strokes = [np.asarray(s, float).reshape(-1, 3) for s in strokes if len(s)]
    if len(strokes) < 2:
        raise InputError("split lobe: draw two or more strokes, one for each new lobe")
    src = hbl.lobes[lobe]
    pts = src.points if len(src.points) else src.hull_vertices
    dist = np.stack([np.linalg.norm(pts[:, None] - s[None], axis=2).min(axis=1) for s in strokes], axis=1)
    owner = dist.argmin(axis=1)
    parts = [_hull_lobe(pts[owner == k], src.branch) for k in range(len(strokes)) if (owner == k).sum() >= 1]
    keep = [lb for j, lb in enumerate(hbl.lobes) if j != lobe]
    return dataclasses.replace(hbl, lobes=(*keep, *parts))
