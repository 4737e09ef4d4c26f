"""The simple rules behind ``FakeSession`` (the real ones live on the server): recombination by
distance, stroke kinds by closure, twigs scattered in lobe boxes, catalog rows.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from arboretum_library.assembly import Assembly, MergeLink, Placement
from arboretum_library.descriptors import describe, tags_for
from arboretum_library.errors import InputError
from arboretum_library.model import HBL, Branch, Example, Level, Provenance
from arboretum_library.protocol import GrownTree

from .assembly_view import placed_hbl
from .demo import octa_lobe
from .session_port import ProgressFn

MERGE_DISTANCE = 0.15
"""Metres: a main-branch base this close to another placement's main branch joins it."""
TWIGS_PER_LOBE = 12


def catalog_row(e: Example) -> dict:
    d = e.descriptors
    return {"id": e.id, "species": e.provenance.species, "source": e.provenance.source, "tags": list(e.tags),
            "lobe_count": d.lobe_count, "curvature": d.curvature, "length": d.length, "spread": d.spread,
            "height": d.height}


def world_structure(example: Example, p: Placement) -> HBL:
    """The example's HBL in the world: lobe transforms (example frame), then scale and T_world_example."""
    return placed_hbl(example.structure, p)


def recombine(a: Assembly, lookup, instance: str) -> tuple[Assembly, tuple[str, ...]]:
    """Link ``instance`` to the placement whose main branch passes nearest its main-branch base (within
    ``MERGE_DISTANCE``): merged into one placement only, as ``Assembly`` requires of its links."""
    if not instance or not any(p.instance == instance for p in a.placements):
        return a, ()
    me = next(p for p in a.placements if p.instance == instance)
    base = world_structure(lookup(me.example_id), me).branches[0].points[0]
    links = tuple(m for m in a.merges if instance not in (m.a, m.b))
    best: tuple[float, MergeLink] | None = None
    for other in a.placements:
        if other.instance == instance:
            continue
        d = np.linalg.norm(world_structure(lookup(other.example_id), other).branches[0].points - base, axis=1)
        if d.min() < MERGE_DISTANCE and (best is None or d.min() < best[0]):
            best = (float(d.min()), MergeLink(other.instance, instance, int(d.argmin()), 0))
    if best is None:
        return dataclasses.replace(a, merges=links), ()
    return dataclasses.replace(a, merges=(*links, best[1])), (best[1].a,)


def sketch_example(strokes: Sequence[np.ndarray], example_id: str) -> tuple[Example, list[str]]:
    """Strokes -> an example: the first open stroke is the main branch, other open strokes secondary
    branches, closed strokes (ends within 25 % of the stroke's extent) lobes around their points."""
    strokes = [np.asarray(s, np.float64).reshape(-1, 3) for s in strokes if len(s) >= 2]
    if not strokes:
        raise InputError("sketch: needs at least one stroke of two or more points")
    kinds = ["lobe" if _closed(s) else "branch" for s in strokes]
    if "branch" not in kinds:
        raise InputError("sketch: draw at least one open stroke for the main branch")
    branches: list[Branch] = []
    lobes = []
    for s, kind in zip(strokes, kinds):
        if kind == "branch":
            parent, vertex = (-1, -1) if not branches else _attach(branches[0].points, s[0])
            level = Level.MAIN if not branches else Level.SECONDARY
            branches.append(Branch(s, np.linspace(0.03 if not branches else 0.012, 0.006, len(s)), parent, vertex, level))
    for s, kind in zip(strokes, kinds):
        if kind == "lobe":
            centre = s.mean(axis=0)
            radius = float(np.linalg.norm(s - centre, axis=1).max())
            tips = np.array([b.points[-1] for b in branches])
            lobes.append(octa_lobe(s, centre, radius * 1.2, int(np.linalg.norm(tips - centre, axis=1).argmin())))
    hbl = HBL(branches[0].points[0], tuple(branches), tuple(lobes), np.concatenate(strokes),
              np.zeros(sum(len(s) for s in strokes), np.uint8))
    d = describe(hbl)
    return Example(example_id, hbl, Provenance("sketch", "0" * 64, "sketch"), d, tags_for(d)), kinds


def _closed(s: np.ndarray) -> bool:
    extent = float(np.ptp(s, axis=0).max())
    return len(s) >= 4 and float(np.linalg.norm(s[0] - s[-1])) < 0.25 * max(extent, 1e-9)


def _attach(main: np.ndarray, p: np.ndarray) -> tuple[int, int]:
    return 0, int(np.linalg.norm(main - p, axis=1).argmin())


def grow_twigs(hbls: list[HBL], seed: int, density: float, progress: ProgressFn) -> GrownTree:
    """Straight twigs from each lobe's secondary-branch tip into its hull box, a leaf at each twig end."""
    rng = np.random.default_rng(seed)
    pos, par, rad, lev = [], [], [], []
    n = 0
    lobes = [lb for h in hbls for lb in h.lobes]
    for k, lb in enumerate(lobes):
        lo, hi = lb.hull_vertices.min(axis=0), lb.hull_vertices.max(axis=0)
        m = max(int(round(TWIGS_PER_LOBE * density)), 1)
        ends = rng.uniform(lo, hi, (m, 3)) * 0.7 + lb.centre * 0.3
        for e in ends:
            pos += [lb.centre, e]
            par += [-1, n]
            rad += [0.004, 0.002]
            lev += [int(Level.TWIG)] * 2
            n += 2
        progress(k + 1, len(lobes), "grow")
    P = np.array(pos).reshape(-1, 3)
    tips = P[1::2]
    normals = rng.normal(size=tips.shape)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-9)
    return GrownTree(positions=P, parents=np.array(par, np.int64), radii=np.array(rad), levels=np.array(lev, np.uint8),
                     leaf_centres=tips, leaf_normals=normals, leaf_sizes=np.full(len(tips), 0.05))


def single_lobe_hbl(points: np.ndarray, labels: np.ndarray | None) -> HBL:
    lo, hi = points.min(axis=0), points.max(axis=0)
    axis = np.linspace([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]], [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2]], 6)
    lobe = octa_lobe(points, points.mean(axis=0), float(np.linalg.norm(hi - lo)) / 2, 0)
    lab = np.zeros(len(points), np.uint8) if labels is None else np.asarray(labels, np.uint8)
    return HBL(axis[0], (Branch(axis, np.linspace(0.05, 0.01, 6)),), (lobe,), points, lab)


def as_example_structure(hbl: HBL) -> HBL:
    """Keep branch 0 as the single MAIN root (others demoted), as an Example requires."""
    bs = tuple(b if i == 0 else dataclasses.replace(b, level=Level.SECONDARY) if b.level == Level.MAIN else b
               for i, b in enumerate(hbl.branches))
    return dataclasses.replace(hbl, branches=bs)
