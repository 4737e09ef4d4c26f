"""Lobes carved round what must pass through them (ours; VRTree's alpha shapes have no such step).

An alpha shape fills the gap where a main branch runs through its foliage, and the alpha shapes of a
lobe a user inserts and the lobe its points came from overlap. ``unwrap`` rebuilds the foreign lobes
wrapped round the main branches near a lobe's centre with that wood carved out; ``part_overlaps`` carves
a lobe round a new lobe whose centre it buried. Both go through ``carve_lobe`` (``lobes.carved_hull``),
which reuses each lobe's plain tetrahedralisation (``remember_plain``) while its members array lives.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np

from .clear import boxes, inside_foreign, main_vertices
from .lobes import RADIUS_STEPS, Tetrahedra, carved_hull, inside, plain_steps
from .memo import ArrayMemo
from .merge import BranchSet, resample_step, sample_polylines
from .state import LobeState


def unwrap(lobes: list[LobeState], j: int, mains: BranchSet, pts: np.ndarray, radius: float,
           near: int = 64, step: float = 0.005) -> int:
    """Carve the main branches out of the foreign lobes that enclose one of the ``near`` main-branch
    vertices nearest lobe ``j``'s centre (the starts ``straight_fallback`` tries); returns how many lobes
    changed (``lobes`` is updated in place).

    A lobe's alpha shape (probe radius 7.7 cm at the 0.8 m scale) fills the gap where a main branch runs
    through its foliage, so a secondary branch leaving that main branch starts inside a lobe it does not
    feed (the pine's lobes wrap its trunk). Each such lobe is rebuilt with the main branches (resampled
    every ``step``) within one probe radius of its points as blockers (``lobes.carved_hull``), at most at
    the probe radius its plain alpha shape used: it then reaches up to the wood but not across it, and
    lies inside the hull it replaces, so no other branch starts crossing. Only hulls change (members,
    centres and branches stay); a lobe wrapped round a trunk can lose its own centre to the tunnel. The
    same blockers every time, so carving a lobe again gives the same shape. A lobe whose carved shape is
    not a closed one-piece surface is kept, and so is one whose carved shape takes in another lobe's branch
    that its hull kept out (a hull carved before round that branch; ``carve_clear``, session 31).
    """
    if not mains.segments:
        return 0
    verts = main_vertices(mains)[0]
    near_pts = verts[np.argsort(np.linalg.norm(verts - lobes[j].centre, axis=1))[:near]]
    wood = sample_polylines(mains.segments, step)
    held = _boxes_hold(boxes(lobes), near_pts)
    changed, branches = 0, []
    for k in map(int, np.flatnonzero(held.any(axis=1))):
        lb = lobes[k]
        if k == j or not inside(lb.hull_vertices, lb.hull_faces, near_pts[held[k]]).any():
            continue
        changed += carve_clear(lobes, k, pts, wood, radius, (j, k), branches, step)
    return changed


def carve_clear(lobes: list[LobeState], k: int, pts: np.ndarray, blockers: np.ndarray, radius: float,
                skip: tuple[int, ...], branches: list, step: float = 0.005) -> bool:
    """``carve_lobe`` refused when it puts a sample of another branch (every ``step``; those of the lobes ``skip``
    left out) inside lobe ``k``'s hull where it lay outside before: carved again with those branches as blockers
    too, else the hull is kept (in place; True when carved). ``branches``: an empty list, or ``_branch_samples``
    of these lobes' branches in it, filled at the first need (``unwrap`` and ``part_overlaps`` change hulls,
    never branches).

    A lobe is carved from its plain tetrahedralisation: the result lies inside its plain hull, not inside one
    carved before round other branches (``tunnel.carve_route``, ``refine._give_way``), whose tunnels it may fill
    (session 31: the leaf-on pine's "around" inserts of lobes 14 and 31 re-carved kept lobe 32 round the trunk
    and filled its tunnel for kept lobe 4's branch, 2.4 mm deep)."""
    lb = lobes[k]
    if not carve_lobe(lobes, k, pts, blockers, radius):
        return False
    if not branches:
        branches.extend(_branch_samples(lobes, step))
    if not _swallows(lb, lobes[k], branches, skip):
        return True
    lobes[k] = lb
    others = branches[0][~np.isin(branches[1], skip)]
    if carve_lobe(lobes, k, pts, np.concatenate([blockers, others]), radius) and \
            not _swallows(lb, lobes[k], branches, skip):
        return True
    lobes[k] = lb
    return False


def _branch_samples(lobes: list[LobeState], step: float) -> tuple[np.ndarray, np.ndarray]:
    """(every lobe's secondary branch resampled every ``step`` (P, 3), each sample's lobe (P,))."""
    parts = [resample_step(lb.segment, step) if len(lb.segment) else np.zeros((0, 3)) for lb in lobes]
    return np.concatenate(parts).reshape(-1, 3), np.repeat(np.arange(len(lobes)), [len(p) for p in parts])


def _swallows(old: LobeState, new: LobeState, branches: list, skip: tuple[int, ...]) -> bool:
    """True if a sample of a branch (``branches``: ``_branch_samples``; those of the lobes ``skip`` left out) lies
    inside ``new``'s hull and outside ``old``'s (``carve_clear``)."""
    q, owner = branches
    lo, hi = new.hull_vertices.min(axis=0), new.hull_vertices.max(axis=0)
    near = ((q > lo) & (q < hi)).all(axis=1) & ~np.isin(owner, skip)
    if not near.any():
        return False
    now = inside(new.hull_vertices, new.hull_faces, q[near])
    return bool(now.any() and (~inside(old.hull_vertices, old.hull_faces, q[near][now])).any())


def _boxes_hold(box: tuple[np.ndarray, np.ndarray], q: np.ndarray) -> np.ndarray:
    """(L, M) bool: which of the points ``q`` (M, 3) lie strictly inside each lobe's hull box (``box``: lo, hi
    (L, 3), ``clear.boxes``), for all lobes at once. ``unwrap`` takes the boxes before it carves: a carving
    replaces lobe k alone, after k's turn (session 24: with a box and a test per lobe, the 11 ``unwrap`` calls
    of the leaf-on pine's split of lobe 17 into 20 took 28 ms of CPU, now 12, on a loaded machine)."""
    lo, hi = box
    return ((q[None] > lo[:, None]) & (q[None] < hi[:, None])).all(axis=2)


_PLAIN = ArrayMemo()
"""The plain tetrahedralisation of each lobe, by its ``members`` array, while that array lives
(kept lobes share it across refinements; not part of ``LobeState``, so it never travels with one)."""


def remember_plain(members: np.ndarray, tet: Tetrahedra) -> None:
    """Keep ``tet`` (``Tetrahedra`` of the points ``members`` indexes) for ``carve_lobe`` while ``members`` lives."""
    _PLAIN.put(members, tet)


def _recall_plain(members: np.ndarray, points: np.ndarray) -> Tetrahedra | None:
    """The ``Tetrahedra`` remembered for ``members`` if it was built from ``points`` (its lobe's points)."""
    tet = _PLAIN.get(members)
    return tet if tet is not None and np.array_equal(tet.source, points) else None


_CARVED = ArrayMemo()
"""Carved shapes of each lobe by its ``members`` array while that lives (with the points array
they index): by (blockers' bytes, radius, steps). ``unwrap`` carves the same lobes with the same wood each
time a branch is routed again, and a carving it undoes is asked for again by the next branch. Not locked:
refinement runs on the server's one loop thread; lobes' arrays are never changed in place (replaced)."""
CARVED_KEPT = 16
"""Carved shapes remembered per lobe (the oldest go first)."""
WORK = {"carvings": 0}
"""Carved shapes computed (not recalled) since the count was last reset (the tests read it)."""


def _carved(members: np.ndarray, pts: np.ndarray) -> dict:
    """The carved shapes remembered for ``members`` indexing ``pts`` (a new, empty store if none): the
    lobe's points, its ``steps`` and ``alpha`` and the blockers decide the shape."""
    hit = _CARVED.get(members)
    if hit is not None and hit[0] is pts:
        return hit[1]
    return _CARVED.put(members, (pts, {}))[1]


def carve_lobe(lobes: list[LobeState], k: int, pts: np.ndarray, blockers: np.ndarray, radius: float,
               pieces: bool = False) -> bool:
    """Rebuild lobe ``k``'s hull with the ``blockers`` (B, 3) within one probe radius of its points kept
    out, at most at its plain probe radius (in place); False when the carved shape is not usable (closed and
    one piece; ``pieces``: or closed in several, ``lobes.carved_hull``). The shape depends on the lobe's
    points, steps and the blockers only, so it is remembered (``_CARVED``)."""
    lb = lobes[k]
    members = pts[lb.members]
    lo, hi = members.min(axis=0) - radius, members.max(axis=0) + radius
    near = np.ascontiguousarray(blockers[((blockers > lo) & (blockers < hi)).all(axis=1)], dtype=np.float64)
    store = _carved(lb.members, pts)
    key = (hashlib.sha1(near.tobytes()).digest(), len(near), float(radius), lb.steps, lb.alpha, pieces)
    if key not in store:
        WORK["carvings"] += 1
        steps = lb.steps if lb.steps is not None else plain_steps(members, radius) if lb.alpha else RADIUS_STEPS
        store[key] = carved_hull(members, radius, near, steps, _recall_plain(lb.members, members), pieces)
        if len(store) > CARVED_KEPT:
            del store[next(iter(store))]
    shape = store[key]
    if shape is None:
        return False
    lobes[k] = replace(lb, hull_vertices=shape[0], hull_faces=shape[1], alpha=True)
    return True


def part_overlaps(lobes: list[LobeState], start: int, mains: BranchSet, pts: np.ndarray, radius: float,
                  step: float = 0.005) -> int:
    """For each lobe from ``start`` on whose centre lies inside another lobe, carve that lobe with the
    first one's points and the main branches as blockers (in place); returns how many hulls changed.

    k-means clusters never need it (no centre of the decomposed test trees lies in another lobe), but
    points a user selects for ``insert_lobe`` border the lobe they came from, and the two alpha shapes
    (probe radius about a lobe's size) overlap: neither branch could reach its centre. Carving fails
    when the blockers split the shape; then the lobe's centre moves to its own point nearest the old
    centre outside every other lobe (its branch ends there), when it has one. A carving that takes in a
    branch the hull kept out is refused as in ``unwrap`` (``carve_clear``).
    """
    wood = sample_polylines(mains.segments, step)
    changed, branches = 0, []
    for j in range(start, len(lobes)):
        c = lobes[j].centre[None]
        lo, hi = boxes(lobes)
        for k in map(int, np.flatnonzero(((c > lo) & (c < hi)).all(axis=1))):
            if k == j or not inside(lobes[k].hull_vertices, lobes[k].hull_faces, c).any():
                continue
            changed += carve_clear(lobes, k, pts, np.concatenate([pts[lobes[j].members], wood]), radius, (j, k),
                                   branches, step)
        if inside_foreign(lobes, j, c)[0]:
            own = pts[lobes[j].members]
            free = own[~inside_foreign(lobes, j, own)]
            if len(free):
                lobes[j] = replace(lobes[j], centre=free[np.argmin(np.linalg.norm(free - c, axis=1))])
    return changed
