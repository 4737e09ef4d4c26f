"""Interactive refinement of a decomposition (VRTree section 3.4, Fig. 5): remove, insert, merge and
split lobes. Each is a pure function ``Decomposition -> Decomposition`` that redoes only what it must:
hulls and secondary branches of the lobes it creates (one Dijkstra on the cached graph, Algorithm 1
step 2 against the cached main branches; a kept lobe wrapped round the main branch where a new branch
must start is carved, ``carve.unwrap``), then the radii and records. A lobe that loses points to
``insert_lobe`` is rebuilt like a new one (centre, hull, branch). A kept lobe's branch that would run
through a new lobe is carved out of it (``_give_way``, in several closed pieces if need be), or, when
that fails, routed again with them. A new lobe's branch that no repair clears (it lies behind another new
lobe: the outer part of a lobe, inserted or split off) is routed round the kept lobes alone, and the new
lobes in its way are carved out of it (``tunnel.behind``, the last step of ``make_lobes``); failing that,
its centre moves to one of its own points that a straight branch reaches clear (``tunnel.moved_centre``).
A piece of a split lobe still crossing after all that runs its branch along the split lobe's own, which
stayed clear, and turns off it to the piece (``tunnel.along``); since session 25 a piece tries that as soon
as its rerouted branch and the straight repair cross, before the bent and carved repairs.
Lobes keep their order; new ones come last (a lobe an insert leaves under 4 points is dropped). Point indices
refer to ``Decomposition.points``; strokes are in the HBL's output frame.
"""

from __future__ import annotations

import operator
import time
from dataclasses import replace

import numpy as np

from arboretum_library.errors import InputError

from .carve import carve_lobe
from .clear import boxes, foreign
from .merge import sample_polylines
from .secondary import make_lobes, zone_sources, zones
from .state import Decomposition, LobeState, build_hbl
from .tunnel import along, enters

ROUTE_ROUNDS = 3
"""Routing rounds of a refinement (``make_lobes`` calls): kept lobes whose branches run through the new
lobes of one round keep their hulls and are routed again in the next, among everything else built so
far; the last round's result stands."""
MIN_LOBE_POINTS = 4
"""Fewest distinct points a lobe made by a refinement holds: four points span a volume, fewer give a
made-up box. An inserted lobe or a split piece needs this many; a lobe an insert leaves with fewer joins
the new lobe."""


def _lobe_index(d: Decomposition, j: int) -> int:
    """``j`` as a lobe number of ``d``; InputError for anything but an integer (bool refused) naming a lobe."""
    have = f"an integer 0..{len(d.lobes) - 1}" if d.lobes else "the tree has no lobes left"
    try:
        if isinstance(j, bool):
            raise TypeError
        j = operator.index(j)
    except TypeError:
        raise InputError(f"lobe {j!r} is not a lobe number ({have})") from None
    if not 0 <= j < len(d.lobes):
        raise InputError(f"lobe {j} does not exist ({f'the tree has {len(d.lobes)} lobes' if d.lobes else have})")
    return j


def _point_indices(d: Decomposition, indices) -> np.ndarray:
    """``indices`` as their distinct (K,) int64 point indices, ascending; InputError unless they are integers
    in range, naming the first one out of range. Checked in the selection's own dtype (a uint64 index of 2**64
    - 1 is not wrapped to -1) and made distinct with a mask of the points, one pass (the same indices):
    ``np.unique`` sorted them, and 64M indices (512 MB, the most a client may send) held the server's loop
    for a median 5.3 s CPU, 0.7 s with the mask, the insert included (session 27, 3 interleaved runs)."""
    n = len(d.points)
    try:
        idx = np.asarray(indices)
    except ValueError:  # nested lists of different lengths
        raise InputError(f"insert lobe: point indices must be integers in 0..{n - 1}, got nested lists of "
                         "different lengths") from None
    if idx.size == 0:
        raise InputError(f"insert lobe: the selection is empty; select 4 or more point indices in 0..{n - 1}")
    if idx.dtype.kind not in "iu":
        raise InputError(f"insert lobe: point indices must be integers in 0..{n - 1}, got {_kind(idx)}")
    idx = idx.reshape(-1)
    out = (idx < 0) | (idx >= n)
    if out.any():
        raise InputError(f"insert lobe: point indices must lie in 0..{n - 1}; {idx[out.argmax()]} does not "
                         f"({np.count_nonzero(out)} of the {idx.size} selected are out of range)")
    picked = np.zeros(n, bool)
    picked[idx] = True
    idx = np.flatnonzero(picked).astype(np.int64)
    if len(idx) < MIN_LOBE_POINTS:
        raise InputError(f"insert lobe: the selection holds {len(idx)} different point(s); a lobe needs at least "
                         f"{MIN_LOBE_POINTS} (it encloses a volume)")
    return idx


def _kind(a: np.ndarray) -> str:
    """What ``a`` holds, for a message: 'float64 values', 'bool values', 'strings', 'objects'."""
    return {"U": "strings", "S": "strings", "O": "objects"}.get(a.dtype.kind, f"{a.dtype} values")


def _strokes(strokes) -> list[np.ndarray]:
    """Each stroke as (S >= 1, 3) finite float64 within ``MAX_COORDINATE`` (as scans are: squared
    distances of 1e300 overflow in k-means); InputError otherwise. Real numbers only: a complex stroke lost
    its imaginary part and a stroke of strings was parsed (before session 27)."""
    from arboretum_library.pointio import MAX_COORDINATE

    out = []
    for k, s in enumerate(strokes if isinstance(strokes, (list, tuple, np.ndarray)) else [None]):
        try:
            a = np.asarray(s)
        except (TypeError, ValueError):
            a = np.zeros((0, 0))
        if a.dtype.kind not in "iuf":
            raise InputError(f"split lobe: stroke {k} must be 1 or more finite 3D points (S, 3) of real numbers, "
                             f"got {_kind(a)}")
        a = a.astype(np.float64)
        if a.ndim != 2 or a.shape[1] != 3 or len(a) == 0 or not np.isfinite(a).all():
            raise InputError(f"split lobe: stroke {k} must be 1 or more finite 3D points (S, 3)")
        if np.abs(a).max() > MAX_COORDINATE:
            raise InputError(f"split lobe: stroke {k} reaches {np.abs(a).max():.3g} m; coordinates beyond "
                             f"{MAX_COORDINATE:.0e} m are refused")
        out.append(a)
    return out


def _finish(d: Decomposition, kept: list[LobeState], groups: list[np.ndarray], centres: np.ndarray,
            t0: float, op: str, order: list[int] | None = None, hbl: bool = True,
            split: tuple[np.ndarray, int, int] | None = None) -> Decomposition:
    """Route the new lobes over ``groups`` after ``kept`` and rebuild the records.

    A new lobe's branch still crossing another new lobe carves its way through it (``tunnel.behind`` in
    ``make_lobes``); a kept lobe whose secondary branch would run through a new lobe is carved out of it,
    else routed again with them.
    ``order`` (one slot per kept lobe and group, in that order) gives each lobe's place in the result.
    ``hbl``: False leaves ``d``'s HBL in place, for a caller that changes the lobes again and builds it once
    (``split_lobe``: ``build_hbl`` is a pure function of the state, so the same HBL either way).
    ``split``: the split lobe's branch (segment, parent, vertex), which the groups' branches may run along in
    the first round (``make_lobes``; the later rounds route kept lobes).
    """
    kept, groups, centres = list(kept), list(groups), list(centres)
    slots = list(order) if order is not None else list(range(len(kept) + len(groups)))
    lobes: list[LobeState] = list(kept)
    hulls: tuple[LobeState, ...] = ()  # the lobes a later round routes again keep their hulls
    sources = _sources(d, [lb.members for lb in kept] + groups)
    for rnd in range(ROUTE_ROUNDS):
        if not groups:
            break
        if sources is None:
            sources = zone_sources(d.points, np.concatenate([lb.members for lb in kept] + groups))
        zone = zones(d.points, [lb.members for lb in kept] + groups, sources)
        lobes = make_lobes(groups, np.array(centres), d.points, d.adjacency, d.root_index, zone, d.mains,
                           d.grid, d.tau, d.options, tuple(kept), (None,) * (len(groups) - len(hulls)) + hulls,
                           split=split if rnd == 0 else None)[0]
        cross = sorted(_crossing_new(lobes, len(kept), d.options.step / 2)) if rnd + 1 < ROUTE_ROUNDS else []
        if cross:  # the new lobes give way to the branches already there, if carving lets them
            _give_way(lobes, len(kept), cross, d.points, d.options.alpha_radius)
            cross = sorted(_crossing_new(lobes, len(kept), d.options.step / 2))
        if not cross:
            break
        # next round: this round's lobes stay, the crossing kept lobes (hulls kept) are routed again
        n = len(kept)
        slots = [slots[i] for i in range(n) if i not in cross] + slots[n:] + [slots[i] for i in cross]
        groups = [lobes[i].members for i in cross]
        centres = [lobes[i].centre for i in cross]
        hulls = tuple(lobes[i] for i in cross)
        kept = [lb for i, lb in enumerate(lobes) if i >= n or i not in cross]
    lobes = [lb for _, lb in sorted(zip(slots, lobes), key=lambda t: t[0])]
    lobe_of = np.full(len(d.points), -1, np.int32)
    for j, lb in enumerate(lobes):
        lobe_of[lb.members] = j
    stats = dict(d.stats, lobes=len(lobes))
    out = replace(d, lobes=tuple(lobes), lobe_of=lobe_of, stats=stats, zone_sources=sources,
                  timing=dict(d.timing, **{op: time.perf_counter() - t0}))
    return replace(out, hbl=build_hbl(out)) if hbl else out


def _sources(d: Decomposition, members: list[np.ndarray]) -> np.ndarray | None:
    """``d.zone_sources`` when the lobes' ``members`` cover the same points as ``d``'s lobes, else None."""
    union = np.zeros(len(d.points), bool)
    for m in members:
        union[m] = True
    return d.zone_sources if d.zone_sources is not None and np.array_equal(union, d.lobe_of >= 0) else None


def _give_way(lobes: list[LobeState], n_kept: int, cross: list[int], pts: np.ndarray, radius: float,
              step: float = 0.0025) -> None:
    """Carve the kept branches of ``cross`` out of the new lobes (indices >= ``n_kept``) they enter (in
    place): rebuilding a new lobe's hull is cheaper than routing a kept branch round it again, and the
    tree the user already has keeps its branches. The carved hull may fall into several closed pieces: a
    lobe merged from clusters either side of the trunk wraps it, and no one-piece shape keeps the branches
    leaving the trunk there out (helper-115's sweep: 8 far merges left 1-9 crossings routing them again)."""
    wood = sample_polylines([lobes[i].segment for i in cross], step)
    for k in range(n_kept, len(lobes)):
        if enters(lobes[k], wood):  # the other new branches stay blockers: keep tunnel.behind's tunnels open
            rest = sample_polylines([lobes[i].segment for i in range(n_kept, len(lobes)) if i != k], step)
            carve_lobe(lobes, k, pts, np.concatenate([wood, rest]), radius, pieces=True)


def _crossing_new(lobes: list[LobeState], n_kept: int, tol: float) -> set[int]:
    """Kept lobes (indices < ``n_kept``) whose secondary branch enters one of the lobes after them (the kept
    lobes' boxes are emptied, so only the new lobes are tried)."""
    lo, hi = (b.copy() for b in boxes(lobes))
    lo[:n_kept], hi[:n_kept] = np.inf, -np.inf
    return {i for i, lb in enumerate(lobes[:n_kept]) if foreign(lobes, i, lb.segment, tol, (lo, hi))}


def remove_lobe(d: Decomposition, j: int) -> Decomposition:
    """Delete lobe ``j`` and its secondary branch (for lobes of irregular shape)."""
    t0 = time.perf_counter()
    _lobe_index(d, j)
    return _finish(d, [lb for k, lb in enumerate(d.lobes) if k != j], [], np.zeros((0, 3)), t0, "remove_lobe")


def _take(d: Decomposition, taken: np.ndarray) -> tuple[list[LobeState], list[np.ndarray], list[int], list[int]]:
    """The lobes with the points ``taken`` removed: (untouched lobes, the remaining members of the lobes
    that lost points (empty ones dropped), and the original index of each, in the same two orders)."""
    mask = np.zeros(len(d.points), bool)
    mask[taken] = True
    kept, shrunk, at_kept, at_shrunk = [], [], [], []
    for k, lb in enumerate(d.lobes):
        keep = lb.members[~mask[lb.members]]
        if len(keep) == len(lb.members):
            kept.append(lb)
            at_kept.append(k)
        elif len(keep):
            shrunk.append(keep)
            at_shrunk.append(k)
    return kept, shrunk, at_kept, at_shrunk


def insert_lobe(d: Decomposition, indices: np.ndarray) -> Decomposition:
    """A new lobe over the selected point ``indices``, taken from the lobes that held them: those get a
    new centre (their remaining points' mean), hull and secondary branch; the new lobe comes last. A lobe
    left with fewer than ``MIN_LOBE_POINTS`` points gives them to the new lobe and is dropped."""
    t0 = time.perf_counter()
    idx = _point_indices(d, indices)
    kept, shrunk, at_kept, at_shrunk = _take(d, idx)
    crumbs = [k for k, g in enumerate(shrunk) if len(g) < MIN_LOBE_POINTS]
    if crumbs:
        idx = np.unique(np.concatenate([idx, *(shrunk[k] for k in crumbs)]))
        shrunk = [g for k, g in enumerate(shrunk) if k not in crumbs]
        at_shrunk = [a for k, a in enumerate(at_shrunk) if k not in crumbs]
    groups = [*shrunk, idx]
    centres = np.array([d.points[g].mean(axis=0) for g in groups])
    rank = {k: r for r, k in enumerate(sorted(at_kept + at_shrunk))}
    order = [rank[k] for k in at_kept + at_shrunk] + [len(rank)]
    return _finish(d, kept, groups, centres, t0, "insert_lobe", order)


def merge_lobes(d: Decomposition, which: list[int]) -> Decomposition:
    """One lobe from the points of the lobes ``which`` (small lobes close together): new alpha shape,
    new secondary branch through Algorithm 1."""
    t0 = time.perf_counter()
    if not isinstance(which, (list, tuple, np.ndarray)):
        raise InputError("merge lobes: give the lobes as a list of lobe numbers")
    sel = sorted({_lobe_index(d, j) for j in which})
    if len(sel) < 2:
        raise InputError("merge lobes: select at least two different lobes")
    idx = np.concatenate([d.lobes[j].members for j in sel])
    kept = [lb for k, lb in enumerate(d.lobes) if k not in sel]
    return _finish(d, kept, [idx], d.points[idx].mean(axis=0)[None], t0, "merge_lobes")


def from_output(d: Decomposition, p: np.ndarray) -> np.ndarray:
    """Output-frame points (..., 3) in the working frame (inverse of ``Decomposition.to_output``)."""
    p = np.asarray(p, dtype=np.float64)
    if d.options.height is None:
        return (p - d.root_scan) * d.scale
    return p / d.output_scale


SEEDS_PER_STROKE = 64
"""At most this many samples of a stroke, evenly spaced along it, seed k-means centres (``split_lobe``)."""
LLOYD_ROUNDS = 10
"""k-means rounds of ``stroke_parts`` (a centre that loses every point stays where it is)."""
STROKE_REACH = 0.5
"""A stroke must come within this share of the lobe's extent (its box diagonal) of the lobe's points."""


def stroke_parts(pts: np.ndarray, strokes: list[np.ndarray], j: int, unit: float) -> np.ndarray:
    """(N,) int: the stroke (index into ``strokes``, working frame) each of the lobe's ``pts`` (N, 3)
    goes to: k-means from every stroke's samples, each centre's points going to its stroke. Before
    session 12 each stroke seeded one centre (its mean) and k-means ran to convergence, which ignored
    the strokes: a stroke over a lobe's top tenth (25 of 247 points) got 113. InputError for a stroke
    far from the lobe or one that keeps no point (``unit``: output units per working unit, for the
    message)."""
    from scipy.spatial import cKDTree

    extent = float(np.linalg.norm(np.ptp(pts, axis=0)))
    near = cKDTree(pts)
    starts = np.cumsum([0] + [len(s) for s in strokes[:-1]])
    gaps = np.minimum.reduceat(near.query(np.concatenate(strokes))[0], starts)  # one query for all strokes
    for k, gap in enumerate(gaps.tolist()):
        if gap > STROKE_REACH * extent:
            raise InputError(f"split lobe: stroke {k} passes {gap * unit:.3g} m from lobe {j}'s points at its "
                             f"nearest (the lobe is {extent * unit:.3g} m across); draw each stroke over the part "
                             "of the lobe it should keep")
    seeds = _seeds(strokes)
    of = np.repeat(np.arange(len(strokes)), [len(x) for x in seeds])
    owner = of[_lloyd(pts, np.concatenate(seeds))]
    empty = [k for k in range(len(strokes)) if not (owner == k).any()]
    if empty:
        raise InputError(f"split lobe: stroke {empty[0]} keeps no point of lobe {j}: every point lies nearer "
                         "another stroke; draw each stroke over the part of the lobe it should keep")
    return owner


def _lloyd(pts: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(N,) int: the centre each of ``pts`` (N, 3) is nearest after ``LLOYD_ROUNDS`` k-means rounds from
    ``centres`` (C, 3). Stops early once a round assigns every point as the round before: the centres then
    come out bit for bit the same, so every later round would repeat it (same result as all rounds)."""
    from scipy.spatial import cKDTree

    nearest = cKDTree(centres).query(pts)[1]
    for _ in range(LLOYD_ROUNDS):
        count = np.bincount(nearest, minlength=len(centres))
        sums = np.stack([np.bincount(nearest, pts[:, a], minlength=len(centres)) for a in range(3)], axis=1)
        centres = np.where(count[:, None] > 0, sums / np.maximum(count, 1)[:, None], centres)
        again = cKDTree(centres).query(pts)[1]
        if np.array_equal(again, nearest):
            break
        nearest = again
    return again


def _seeds(strokes: list[np.ndarray]) -> list[np.ndarray]:
    """Up to ``SEEDS_PER_STROKE`` samples (M_k, 3) of each stroke, evenly spaced, none repeating an
    earlier stroke's (InputError when a stroke is all repeats: two equal strokes would split at random)."""
    out, seen = [], set()
    for k, s in enumerate(strokes):
        pick = s[np.unique(np.linspace(0, len(s) - 1, min(len(s), SEEDS_PER_STROKE)).round().astype(int))]
        pick = pick[[tuple(p) not in seen for p in pick.tolist()]]
        if not len(pick):
            raise InputError(f"split lobe: stroke {k} only repeats the points of earlier strokes")
        seen.update(map(tuple, pick.tolist()))
        out.append(pick)
    return out


def split_lobe(d: Decomposition, j: int, strokes: list[np.ndarray], seed: int = 0) -> Decomposition:
    """Split lobe ``j`` into one lobe per stroke (VRTree: "sampled points from these strokes serving as
    initial clustering centers for the K-means algorithm"): up to ``SEEDS_PER_STROKE`` samples of each
    stroke (S_k, 3), output frame, seed one k-means centre each, and a point goes to the stroke whose
    centre it ends nearest (``stroke_parts``). ``seed`` is checked and kept for callers: the split is
    deterministic."""
    t0 = time.perf_counter()
    lb = d.lobes[_lobe_index(d, j)]
    strokes = _strokes(strokes)
    try:
        if isinstance(seed, bool) or operator.index(seed) < 0:
            raise TypeError
    except TypeError:
        raise InputError(f"split lobe: the seed must be an integer >= 0, got {seed!r}") from None
    if len(strokes) < 2:
        raise InputError("split lobe: draw at least two strokes (one per new lobe)")
    if len(strokes) * MIN_LOBE_POINTS > len(lb.members):
        raise InputError(f"split lobe: {len(strokes)} strokes for a lobe of {len(lb.members)} points (each new "
                         f"lobe needs at least {MIN_LOBE_POINTS})")
    pts = d.points[lb.members]
    owner = stroke_parts(pts, [from_output(d, s) for s in strokes], j, d.output_scale)
    groups = [lb.members[owner == k] for k in range(len(strokes))]
    if (small := [k for k, g in enumerate(groups) if len(g) < MIN_LOBE_POINTS]):
        raise InputError(f"split lobe: stroke {small[0]} keeps {len(groups[small[0]])} point(s) of lobe {j}; each new "
                         f"lobe needs at least {MIN_LOBE_POINTS}: draw it over more of the lobe")
    centres = np.array([d.points[g].mean(axis=0) for g in groups])
    kept = [x for k, x in enumerate(d.lobes) if k != j]
    branch = (lb.segment, lb.parent, lb.parent_vertex) if lb.parent >= 0 and len(lb.segment) >= 2 else None
    out = _finish(d, kept, groups, centres, t0, "split_lobe", hbl=False, split=branch)
    return _along_split(out, lb, len(kept), t0)


def _along_split(d: Decomposition, split: LobeState, n_kept: int, t0: float) -> Decomposition:
    """``d`` (its HBL not yet built) with each piece of the ``split`` lobe (lobes ``n_kept`` on) whose branch
    still enters another lobe given a branch along the split lobe's own, when one clears it (``tunnel.along``),
    and its HBL built once (before session 24 also for ``_finish``, and dropped here). Dozens of pieces
    packed into one lobe's place leave no route from the main branches clear to the inner ones (session 23's probe: on a pine, 8 of 37 splits in 20 left 3-12 pieces each
    whose branch ran 3 cm deep through a kept lobe)."""
    lobes = list(d.lobes)
    tol = d.options.step / 2
    bad = [k for k in range(n_kept, len(lobes)) if foreign(lobes, k, lobes[k].segment, tol, boxes(lobes))]
    if not bad or split.parent < 0 or len(split.segment) < 2:
        return replace(d, hbl=build_hbl(d))
    for k in bad:
        along(lobes, n_kept, k, (split.segment, split.parent, split.parent_vertex), d.points, d.options)
    out = replace(d, lobes=tuple(lobes), timing=dict(d.timing, split_lobe=time.perf_counter() - t0))
    return replace(out, hbl=build_hbl(out))
