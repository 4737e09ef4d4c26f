"""Keeping a secondary branch out of the lobes it does not feed: the inside tests, and the two repairs that
replace a routed branch which still enters a foreign lobe (VRTree has neither; ours, see secondary.py):

- ``straight_fallback``: a straight segment from the nearest main-branch vertex whose segment to the
  lobe centre stays clear;
- ``bent_fallback``: a two-piece branch, main vertex -> one of the lobe's own points -> lobe centre
  (every (n // ``waypoints``)-th of its n points, 32-63 of them, whose segment to the centre is
  clear).

Both ask hundreds of times per refinement whether points or segments enter a foreign lobe. The hulls
are packed once per set of hulls (``_packed``) and tested in one compiled loop (``hullpack.inside_any``,
``hullpack.segments_blocked``): a point stops at the first lobe holding it, a segment at its first sample
inside one (session 14: the same answers as testing every sample lobe by lobe, a tenth of the tests).
"""

from __future__ import annotations

import functools
import threading
import weakref
from collections import OrderedDict
from operator import attrgetter, is_

import numpy as np

from .blockers import Blockers, Pairs, own_rows
from .hullpack import (
    HullPack,
    any_inside,
    any_inside_along,
    clear_prefix,
    first_clear_route,
    inside_any,
    join_packs,
    pack_hull,
    segments_blocked,
    splice_packs,
    vertex_first,
)
from .memo import ArrayMemo
from .merge import BranchSet, resample_step
from .state import LobeState

WORK = {"hull_tests": 0}
"""(point, lobe) inside tests made by ``inside_foreign`` and the repairs since the count was last reset:
a measure of their work that does not depend on the machine (the tests read it)."""

_PACKS: OrderedDict[tuple[int, ...], tuple[list[np.ndarray], HullPack, tuple[np.ndarray, np.ndarray]]] = OrderedDict()
"""The ``HullPack`` and boxes of the last ``PACKS_KEPT`` sets of hulls, by the ids of their arrays (which the
entry holds, so the ids stay theirs): a refinement asks about the same lobes hundreds of times between two
hull changes."""
PACKS_KEPT = 8
_PACKS_LOCK = threading.Lock()
_VERTICES, _FACES = attrgetter("hull_vertices"), attrgetter("hull_faces")
_HULLS = ArrayMemo()
"""Each hull's faces, own ``HullPack`` and box (lo (3,), hi (3,)), by its vertex array while that lives."""


def _hull(lb: LobeState) -> tuple[HullPack, np.ndarray, np.ndarray]:
    """Lobe ``lb``'s hull as a ``HullPack`` with its box, built once per hull."""
    verts, faces = lb.hull_vertices, lb.hull_faces
    hit = _HULLS.get(verts)
    if hit is not None and hit[0] is faces:
        return hit[1:]
    return _HULLS.put(verts, (faces, pack_hull(verts, faces), verts.min(axis=0), verts.max(axis=0)))[1:]


_LAST: list = [None]
"""The last lobes ``_packed`` was asked about (a tuple: they hold their hulls), its answer, and their hull
vertex and face arrays (tuples): a refinement's
repairs ask about the very same lobes hundreds of times in a row, and telling them apart by identity costs a
tenth of building the key (session 23: 0.8 against 9.2 us a call with 59 lobes, 1.8 against 23 with 106)."""


def _packed(lobes: list[LobeState]) -> tuple[HullPack, tuple[np.ndarray, np.ndarray]]:
    """The ``HullPack`` of the lobes' hulls and their boxes (lo (L, 3), hi (L, 3)), built once per set of hulls.
    The last answer stands while every lobe holds the same hull arrays (session 24: a lobe replaced with a new
    branch keeps its hull, and its lobe list asked again, 63 of the 78 misses of a pine split into 20, built
    the ids key again)."""
    last = _LAST[0]
    if lobes and last is not None and len(last[0]) == len(lobes):
        if all(map(is_, last[0], lobes)):
            return last[1]
        if all(map(is_, last[2], map(_VERTICES, lobes))) and all(map(is_, last[3], map(_FACES, lobes))):
            _LAST[0] = (tuple(lobes), *last[1:])
            return last[1]
    found = _packed_by_hulls(lobes)
    _LAST[0] = (tuple(lobes), found, tuple(map(_VERTICES, lobes)), tuple(map(_FACES, lobes)))
    return found


def _packed_by_hulls(lobes: list[LobeState]) -> tuple[HullPack, tuple[np.ndarray, np.ndarray]]:
    """``_packed`` by the ids of the lobes' hull arrays (lobes replaced with their hulls kept hit it)."""
    key = (*map(id, map(_VERTICES, lobes)), *map(id, map(_FACES, lobes)))
    with _PACKS_LOCK:
        hit = _PACKS.get(key)
        if hit is not None:
            _PACKS.move_to_end(key)
            return hit[1], hit[2]
    pack, box = _joined(lobes)
    for a in box:
        a.flags.writeable = False  # shared by every caller until the hulls change
    with _PACKS_LOCK:
        _PACKS[key] = ([*map(_VERTICES, lobes), *map(_FACES, lobes)], pack, box)
        while len(_PACKS) > PACKS_KEPT:
            _PACKS.popitem(last=False)
    return pack, box


_JOINED: list = [None]
"""The last pack ``_joined`` made: (hull vertex arrays, face arrays (tuples: they hold them), the pack, its
``vertex_first``, the hulls' boxes)."""
SPLICE_MOST = 0.25
"""``_joined`` splices the last pack when at most this share of its hulls changed (else joins every hull)."""


def _joined(lobes: list[LobeState]) -> tuple[HullPack, tuple[np.ndarray, np.ndarray]]:
    """``join_packs`` of the lobes' hulls' packs and their boxes (lo (L, 3), hi (L, 3)): the same arrays, spliced
    from the last ones made when the lobes hold the same hull arrays but for a few (``hullpack.splice_packs``, the
    changed rows of the boxes set; session 29: ``carve_route`` and ``along`` pack every trial list of a split's 60
    lobes with 1-3 hulls carved again, 0.75 ms each)."""
    verts, faces = tuple(map(_VERTICES, lobes)), tuple(map(_FACES, lobes))
    last = _JOINED[0]
    if lobes and last is not None and len(last[0]) == len(lobes):
        changed = [i for i in range(len(lobes)) if verts[i] is not last[0][i] or faces[i] is not last[1][i]]
        if len(changed) <= SPLICE_MOST * len(lobes):
            new = {i: _hull(lobes[i]) for i in changed}
            pack = splice_packs(last[2], last[3], {i: p[0] for i, p in new.items()})
            lo, hi = last[4][0].copy(), last[4][1].copy()
            n_verts = np.diff(last[3])
            for i, p in new.items():
                lo[i], hi[i], n_verts[i] = p[1], p[2], len(p[0].vertices)
            _JOINED[0] = (verts, faces, pack, np.r_[0, np.cumsum(n_verts)].astype(np.int64), (lo, hi))
            return pack, (lo, hi)
    parts = [_hull(lb) for lb in lobes]
    packs = [p[0] for p in parts]
    pack = join_packs(packs)
    box = (np.array([p[1] for p in parts]).reshape(-1, 3), np.array([p[2] for p in parts]).reshape(-1, 3))
    _JOINED[0] = (verts, faces, pack, vertex_first(packs), box)
    return pack, box


def _pack_and_box(lobes: list[LobeState], box: tuple[np.ndarray, np.ndarray] | None) -> tuple[HullPack, tuple]:
    """The lobes' joined hulls (``_packed``) and the boxes to test them by: ``box`` when given, else their own."""
    pack, own = _packed(lobes)
    return pack, (box if box is not None else own)


def boxes(lobes: list[LobeState]) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes (lo (L, 3), hi (L, 3)) of the lobes' hulls."""
    return _packed(lobes)[1]


def kept_boxes(lobes: list[LobeState], n_kept: int) -> tuple[np.ndarray, np.ndarray]:
    """The lobes' boxes with every box from ``n_kept`` on emptied (lo inf, hi -inf): a test against them tries
    the lobes before ``n_kept`` alone, in the same order and with the same hull tests as one against the list
    of those lobes (and any lobe it skips) would, without packing that list's hulls again (session 25)."""
    lo, hi = (b.copy() for b in boxes(lobes))
    lo[n_kept:], hi[n_kept:] = np.inf, -np.inf
    return lo, hi


def inside_foreign(lobes: list[LobeState], j: int, q: np.ndarray,
                   box: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(M,) bool: which of the points ``q`` (M, 3) lie inside a lobe other than ``j`` (a lobe is tested
    only for points inside ``box``, its bounding box by default; ``hullpack.inside_any``)."""
    pack, (lo, hi) = _pack_and_box(lobes, box)
    out, tests = inside_any(pack, lo, hi, j, q)
    WORK["hull_tests"] += tests
    return out


def foreign(lobes: list[LobeState], j: int, seg: np.ndarray, tol: float,
            box: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """True if a vertex of ``seg`` (resampled every ``tol``) lies inside a lobe other than ``j``: the answer of
    ``inside_foreign(...).any()``, its vertices tried up to the first one inside (``hullpack.any_inside``;
    session 27: the bench's 8 splits in 20 made 142,705 hull tests in their point tests, 24,224 this way)."""
    pack, (lo, hi) = _pack_and_box(lobes, box)
    found, tests, done = any_inside_along(pack, lo, hi, j, seg, tol)  # session 29: one compiled call
    if not done:  # a segment ``resample_step`` leaves to its numpy reference
        found, tests = any_inside(pack, lo, hi, j, resample_step(seg, tol))
    WORK["hull_tests"] += tests
    return found


def first_clear_along(lobes: list[LobeState], j: int, seg: np.ndarray, centre: np.ndarray, order: np.ndarray,
                      counts: np.ndarray, tol: float, box: tuple[np.ndarray, np.ndarray] | None = None,
                      clear: np.ndarray | None = None) -> tuple[int, int]:
    """(i, resume): the first i whose route (``seg`` up to its vertex ``order[i]``, then ``counts[i]`` points
    evenly to ``centre``: ``tunnel._along_route``) ``foreign`` finds clear, -1 for none, the routes made and
    tested in one compiled call up to that one (``hullpack.first_clear_route``: the same answers and hull
    tests). ``resume`` >= 0: the routes from ``resume`` on are left to the caller (one resampled to nothing).
    ``clear`` (R,) bool, when given: every route tried and each clear one's entry set (``i`` is then -1)."""
    pack, (lo, hi) = _pack_and_box(lobes, box)
    i, tests, resume = first_clear_route(pack, lo, hi, j, seg, centre, order, counts, tol, clear=clear)
    WORK["hull_tests"] += tests
    return i, resume


def clear_prefix_length(lobes: list[LobeState], j: int, seg: np.ndarray, tol: float,
                        box: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[int, int]:
    """(ok, resume): how many of ``seg``'s first prefixes ``foreign`` finds clear in turn, up to the first it
    does not, in one compiled call (``hullpack.clear_prefix``: the same answers and hull tests). ``resume`` >= 0:
    the prefixes from ``seg[:resume + 1]`` on are left to the caller (``ok`` is then ``resume``)."""
    pack, (lo, hi) = _pack_and_box(lobes, box)
    ok, tests, resume = clear_prefix(pack, lo, hi, j, seg, tol)
    WORK["hull_tests"] += tests
    return ok, resume


_MAIN_VERTICES = ArrayMemo()
"""``main_vertices`` by the first main segment's array, with the segments it was computed for: the repairs
ask for it hundreds of times per refinement (a BranchSet's arrays are replaced, never changed in place)."""


def main_vertices(mains: BranchSet) -> tuple[np.ndarray, np.ndarray]:
    """Every main-branch vertex (V, 3) and its (segment, vertex index) (V, 2) (read only: shared)."""
    segs = mains.segments
    hit = _MAIN_VERTICES.get(segs[0]) if segs else None
    if hit is not None and len(hit[0]) == len(segs) and all(w() is a for w, a in zip(hit[0], segs)):
        return hit[1]
    owner = np.concatenate([np.stack([np.full(len(s), b), np.arange(len(s))], 1) for b, s in enumerate(segs)])
    out = (np.concatenate(segs), owner)
    for a in out:
        a.flags.writeable = False
    if segs:
        _MAIN_VERTICES.put(segs[0], ([weakref.ref(a) for a in segs], out))
    return out


def straight_fallback(lobes: list[LobeState], j: int, mains: BranchSet, tries: int = 64,
                      step: float = 0.005) -> tuple[np.ndarray, int, int] | None:
    """A straight secondary branch for lobe ``j`` from the nearest main-branch vertex whose segment to the
    lobe centre stays out of foreign lobes (candidates tested nearest first, up to the first clear one), or
    None."""
    found = straight_from(lobes, j, lobes[j].centre[None], mains, tries, step)
    return None if found is None else found[1]


def straight_from(lobes: list[LobeState], j: int, centres: np.ndarray, mains: BranchSet, tries: int = 64,
                  step: float = 0.005, own: tuple[np.ndarray, np.ndarray] | None = None,
                  ) -> tuple[int, tuple[np.ndarray, int, int]] | None:
    """(k, branch): the first of the ``centres`` (C, 3) that ``straight_fallback`` reaches with a straight
    branch were it lobe ``j``'s centre (its hull unchanged), and that branch; None if none is reached. One
    ``first_clear`` call over every (centre, vertex) pair in that order: before session 23 a ``blocked`` call
    per 8 vertices of each centre (``tunnel.moved_centre`` tries up to 32 centres). ``own``: (each centre's
    position among lobe ``j``'s members, the points they index) when the centres are its own points (the known
    blockers name them so, ``Pairs``)."""
    verts, owner = main_vertices(mains)
    orders = _nearest_each(verts, centres, tries)
    if not sum(map(len, orders)):
        return None
    which = np.repeat(np.arange(len(centres)), [len(o) for o in orders])
    cand = np.concatenate(orders)
    pairs = Pairs(verts, cand, centres, which, *(own or (None, None)))
    k = first_clear(lobes, j, verts[cand], centres[which], step, boxes(lobes), cand, pairs=pairs)  # a start once
    if k < 0:
        return None
    return int(which[k]), _straight(verts[cand[k]], centres[which[k]], owner[cand[k]])


def straight_routes(lobes: list[LobeState], j: int, mains: BranchSet, tries: int = 64,
                    step: float = 0.005, box: tuple[np.ndarray, np.ndarray] | None = None,
                    ) -> list[tuple[np.ndarray, int, int]]:
    """Every straight branch ``straight_fallback`` could give lobe ``j``: from each of the ``tries`` main-branch
    vertices nearest its centre whose segment stays out of foreign lobes, nearest first (the last resort
    ``tunnel.behind`` chooses among them). ``box``: the lobes' boxes to test against (``boxes(lobes)`` by
    default; a lobe whose box is emptied is left out, see ``kept_boxes``)."""
    centre = lobes[j].centre
    verts, owner = main_vertices(mains)
    order = _nearest_vertices(verts, centre, tries)
    if not len(order):
        return []
    bad = blocked(lobes, j, verts[order], np.broadcast_to(centre, (len(order), 3)), step,
                  boxes(lobes) if box is None else box, pairs=Pairs(verts, order, centre[None], np.zeros(len(order), int)))
    return [_straight(verts[i], centre, owner[i]) for i in order[~bad]]


def _nearest_vertices(verts: np.ndarray, centre: np.ndarray, tries: int) -> np.ndarray:
    """Indices of the ``tries`` vertices nearest ``centre``, nearest first, the centre itself left out."""
    dist = np.linalg.norm(verts - centre, axis=1)
    order = np.argsort(dist)[:tries]
    return order[dist[order] > 1e-9]


def _nearest_each(verts: np.ndarray, centres: np.ndarray, tries: int) -> list[np.ndarray]:
    """``_nearest_vertices`` of each of the ``centres`` (C, 3), the distances of all computed at once: the same
    float operations (``np.linalg.norm`` is the root of the summed squares), each row sorted alone (session 24:
    ``tunnel.moved_centre`` asks for up to 32 centres at a time)."""
    diff = verts[None, :, :] - np.asarray(centres, np.float64).reshape(-1, 1, 3)
    dist = np.sqrt(np.add.reduce(diff * diff, axis=2))
    order = np.argsort(dist, axis=1)[:, :tries]
    return [o[d[o] > 1e-9] for o, d in zip(order, dist)]


def _straight(start: np.ndarray, centre: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The segment ``start`` -> ``centre`` every <= 1 cm, with the (branch, vertex) it leaves from."""
    m = max(2, int(np.ceil(np.linalg.norm(centre - start) / 0.01)) + 1)
    return start + unit_steps(m) * (centre - start), int(owner[0]), int(owner[1])


UNIT_STEPS_KEPT = 1024
"""``unit_steps`` keeps its answers for m up to this many steps (10 m of branch at 1 cm)."""


def unit_steps(m: int) -> np.ndarray:
    """``np.linspace(0.0, 1.0, m)[:, None]`` (m, 1), read only: made once per m up to ``UNIT_STEPS_KEPT``
    (session 27: ``tunnel.along`` makes about 100 routes a split, each with its own)."""
    return _unit_steps(m) if m <= UNIT_STEPS_KEPT else np.linspace(0.0, 1.0, m)[:, None]


@functools.cache
def _unit_steps(m: int) -> np.ndarray:
    """``unit_steps`` for one m, kept."""
    out = np.linspace(0.0, 1.0, m)[:, None]
    out.flags.writeable = False
    return out


def blocked(lobes: list[LobeState], j: int, a: np.ndarray, b: np.ndarray, step: float,
             box: tuple[np.ndarray, np.ndarray], start_ids: np.ndarray | None = None,
             pairs: Pairs | None = None) -> np.ndarray:
    """(S,) bool: segments a[i] -> b[i] ((S, 3) each), sampled every ~``step``, with a sample inside a lobe
    other than ``j`` (``hullpack.segments_blocked``: every 4th sample first, and a segment stops at its first
    sample inside: most blocked segments show it early; ``start_ids``: equal for equal starts ``a``).
    ``pairs``: the same segments as ``Pairs`` (from main vertices): the hulls known to block them for lobe ``j``
    are used and kept (``blockers.Blockers``)."""
    return _segments(lobes, j, a, b, step, box, start_ids, pairs, False)


def first_clear(lobes: list[LobeState], j: int, a: np.ndarray, b: np.ndarray, step: float,
                box: tuple[np.ndarray, np.ndarray], start_ids: np.ndarray | None = None,
                pairs: Pairs | None = None) -> int:
    """The first i whose segment a[i] -> b[i] ``blocked`` finds clear, -1 for none; the segments after it
    are not tried."""
    bad = _segments(lobes, j, a, b, step, box, start_ids, pairs, True)
    return -1 if bad.all() else int(np.argmin(bad))


def _segments(lobes: list[LobeState], j: int, a: np.ndarray, b: np.ndarray, step: float,
              box: tuple[np.ndarray, np.ndarray], start_ids: np.ndarray | None, pairs: Pairs | None,
              until_clear: bool) -> np.ndarray:
    """``blocked`` (or with ``until_clear``, ``first_clear``'s answers) with the known blockers of ``pairs``."""
    counts = _sample_counts(a, b, step)
    pack, own = _packed(lobes)
    memo = None if pairs is None else Blockers.of(lobes[j], pairs.verts, step)
    held = None if memo is None else own_rows(box, own, j)
    prior = None if memo is None else memo.prior(lobes, j, held, pairs, _hull_index(lobes))
    by = None if memo is None else np.full(len(a), -1, np.int64)
    bad, tests = segments_blocked(pack, box[0], box[1], j, a, b, counts, until_clear=until_clear,
                                  start_ids=start_ids, prior=prior, by=by)
    WORK["hull_tests"] += tests
    if memo is not None:
        memo.keep(lobes, j, held, pairs, by)
    return bad


_INDEX: list = [None, {}]
"""The hull vertex arrays of the lobes ``_packed`` was last asked about (its tuple) and the index of each by id."""


def _hull_index(lobes: list[LobeState]) -> dict[int, int]:
    """{id of a lobe's hull vertex array: its index} for ``lobes`` (the last lobes ``_packed`` was asked about;
    built once per set of hulls)."""
    verts = _LAST[0][2] if _LAST[0] is not None and len(_LAST[0][2]) == len(lobes) else tuple(map(_VERTICES, lobes))
    if _INDEX[0] is not verts:
        _INDEX[:] = [verts, {id(v): k for k, v in enumerate(verts)}]
    return _INDEX[1]


def _sample_counts(a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
    """(S,) samples every ~``step`` along the segments a[i] -> b[i], both ends included (at least 2)."""
    return np.maximum(2, np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(int) + 1)


def _segment_samples(a: np.ndarray, b: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ~``step`` along the segments a[i] -> b[i] ((S, 3) each) and the segment of each (the
    samples ``blocked`` makes one by one, for tests)."""
    counts = _sample_counts(a, b, step)
    which = np.repeat(np.arange(len(a)), counts)
    first = np.cumsum(counts) - counts
    i = np.arange(len(which)) - first[which]
    t = i * (1.0 / (counts - 1))[which]  # np.linspace(0, 1, count) for each segment, bit for bit
    t[first + counts - 1] = 1.0
    t = t[:, None]
    return a[which] + t * (b[which] - a[which]), which


def _outside_first(lobes: list[LobeState], j: int, verts: np.ndarray, order: np.ndarray, count: int,
                   box: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The first ``count`` of ``order`` (indices into ``verts``) whose vertex lies outside every lobe but ``j``
    (a start in a foreign lobe fails), tested ``count`` at a time up to the last one needed: the same as
    testing them all (before session 23: every main vertex, 256 of the leaf-on pine's, for 48)."""
    keep = []
    for at in range(0, len(order), count):
        part = order[at:at + count]
        keep.append(part[~inside_foreign(lobes, j, verts[part], box)])
        if sum(map(len, keep)) >= count:
            break
    return np.concatenate(keep)[:count] if keep else order[:0]


def bent_fallback(lobes: list[LobeState], j: int, mains: BranchSet, pts: np.ndarray, waypoints: int = 32,
                  tries: int = 48, batch: int = 2, step: float = 0.005,
                  box: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, int, int] | None:
    """A two-piece secondary branch for lobe ``j``: main-branch vertex -> one of the lobe's own points ->
    lobe centre, both pieces clear of foreign lobes, through every (n // ``waypoints``)-th of the lobe's
    n points whose segment to the centre is clear. The ``tries`` main vertices nearest the centre that
    lie outside every foreign lobe are tested ``batch`` at a time, nearest first; the first batch with a
    clear route gives the shortest one. None if none has one. For lobes that no straight segment reaches
    (lobes around a pine's trunk). The pairs are tested in one ``first_clear`` call up to the first clear one,
    then its batch in full (before session 23: a ``blocked`` call per batch, up to 24). ``box``: as in
    ``straight_routes``."""
    centre, box = lobes[j].centre, boxes(lobes) if box is None else box
    members = pts[lobes[j].members]
    spacing = max(1, len(members) // waypoints)
    every = members[::spacing]
    at = np.flatnonzero(~blocked(lobes, j, every, np.broadcast_to(centre, every.shape), step, box))
    w = every[at]
    if not len(w):
        return None
    verts, owner = main_vertices(mains)
    order = _outside_first(lobes, j, verts, np.argsort(np.linalg.norm(verts - centre, axis=1)), tries, box)
    v = np.repeat(order, len(w))  # every (vertex, waypoint) pair, batch after batch
    ww = np.tile(w, (len(order), 1))
    at = np.tile(at, len(order))  # each pair's waypoint among ``every``, which are members 0, spacing, ...
    named = (np.arange(0, len(members), spacing), pts)
    # the batch of the first clear pair is the first batch with one
    first = first_clear(lobes, j, verts[v], ww, step, box, v, pairs=Pairs(verts, v, every, at, *named))
    if first < 0:
        return None
    size = batch * len(w)
    v, ww, at = (x[first // size * size:][:size] for x in (v, ww, at))
    bad = blocked(lobes, j, verts[v], ww, step, box, v, pairs=Pairs(verts, v, every, at, *named))
    length = np.where(bad, np.inf, np.linalg.norm(ww - verts[v], axis=1) + np.linalg.norm(ww - centre, axis=1))
    k = int(np.argmin(length))
    a, b = verts[v[k]], ww[k]
    seg = np.vstack([resample_step(np.stack([a, b]), 0.01), resample_step(np.stack([b, centre]), 0.01)[1:]])
    return seg, int(owner[v[k], 0]), int(owner[v[k], 1])
