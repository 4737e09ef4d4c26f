"""Last resorts for a lobe whose secondary branch still crosses another lobe after every repair of
``secondary.make_lobes`` (ours; VRTree has no such guarantee): a straight or bent branch carved through
the lobes in its way, the straight one through the fewest (``behind``, ``_routes``, ``carve_route``),
else the lobe's centre moved to one of its own points that a straight branch reaches clear
(``moved_centre``). ``make_lobes`` runs them last, on the lobes it makes: a refinement's new lobes, or
every lobe of a decomposition.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from .carve import carve_lobe
from .clear import (
    bent_fallback,
    blocked,
    boxes,
    clear_prefix_length,
    first_clear,
    first_clear_along,
    foreign,
    inside_foreign,
    kept_boxes,
    main_vertices,
    straight_from,
    straight_routes,
    unit_steps,
)
from .lobes import inside
from .merge import BranchSet, resample_step, sample_polylines
from .meshdist import surface_distances
from .options import DecomposeOptions
from .state import LobeState


def enters(lb: LobeState, wood: np.ndarray, box: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """True if one of the points ``wood`` (W, 3) lies inside lobe ``lb``'s hull (``box``: its hull's box, the
    least and greatest of its vertices, when known: ``clear.boxes`` keeps it)."""
    lo, hi = box if box is not None else (lb.hull_vertices.min(axis=0), lb.hull_vertices.max(axis=0))
    near = wood[((wood > lo) & (wood < hi)).all(axis=1)]
    return bool(len(near) and inside(lb.hull_vertices, lb.hull_faces, near).any())


def _boxes_meet(lo: np.ndarray, hi: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(L,) bool: whether each box (``lo``, ``hi`` (L, 3)) may strictly hold one of the points ``q`` (Q, 3): False
    only where none of them lies strictly inside it (the box of ``q``, its nan left out as the strict tests leave
    them, misses it), so ``enters`` and
    ``lobes_entered`` skip those lobes with the same answers (session 29)."""
    if not len(q):
        return np.zeros(len(lo), bool)
    return ((np.fmin.reduce(q, axis=0) < hi) & (np.fmax.reduce(q, axis=0) > lo)).all(axis=1)  # nan: left out


def lobes_entered(lobes: list[LobeState], which: list[int], woods: list[np.ndarray]) -> np.ndarray:
    """(W,) int: how many of the lobes ``which`` each of ``woods`` ((P_i, 3) each) enters: ``enters`` for
    every pair, one inside test per lobe over all the woods' points in its box (session 21: ``_routes``
    asked 64 routes x the other new lobes one pair at a time, 7 of an "around" insert's 90 ms)."""
    count = np.zeros(len(woods), np.int64)
    if not woods:
        return count
    owner = np.repeat(np.arange(len(woods)), [len(w) for w in woods])
    q = np.concatenate(woods)
    los, his = boxes(lobes)  # each hull's box, kept (session 28: not its vertices' least and greatest again)
    meets = _boxes_meet(los, his, q)
    for k in which:
        if not meets[k]:  # no point in its box: no hit
            continue
        lb, lo, hi = lobes[k], los[k], his[k]
        near = ((q > lo) & (q < hi)).all(axis=1)
        hit = np.zeros(len(woods), bool)
        hit[owner[near][inside(lb.hull_vertices, lb.hull_faces, q[near])]] = True
        count += hit
    return count


def behind(lobes: list[LobeState], n_kept: int, pts: np.ndarray, mains: BranchSet, o: DecomposeOptions,
           step: float = 0.0025) -> int:
    """A new lobe (index >= ``n_kept``) whose own branch still crosses a lobe (no repair of ``make_lobes``
    cleared it) gets a straight or bent repair among the kept lobes alone (``_routes``: the straight ones
    through the fewest other new lobes first), and the other new lobes in its way are carved out of it,
    when that clears it (in place; else its centre moves, ``moved_centre``).
    Returns how many lobes it was asked to clear.

    In a refinement such a lobe lies behind another new one: the outer part of a lobe that was inserted or
    split off, with the part left between it and the main branches, so every route to it runs through that
    part. A decomposition (``n_kept`` 0: every lobe is new) has one where the lobes packed round a
    conifer's leader leave no clear way to a lobe at its top (session 15: one of 180 fresh synthetic
    runs, the virtual scanner's pine seed 13 leaf-on, whose branch ran 0.56 of the height up the crown
    through 8 lobes). A re-carved hull keeps out of the new blockers only and may fill a tunnel cut
    before for another branch: ``entered`` refuses such a result, and the carving is tried again with
    every other branch as a blocker too (refinement's ``_give_way`` likewise keeps the other new branches
    as blockers when it carves a new lobe again).
    """
    tol, asked = o.step / 2, 0
    for j in range(n_kept, len(lobes)):
        if not foreign(lobes, j, lobes[j].segment, tol, boxes(lobes)):
            continue
        asked += 1
        if not any(carve_route(lobes, n_kept, j, route, pts, o, step)
                   for route in _routes(lobes, n_kept, j, pts, mains, step)):
            moved_centre(lobes, j, pts, mains)
            if buried(lobes, j, pts):
                shallow_centre(lobes, j, pts, mains)
    return asked


ROUTES_TRIED = 4
"""``behind`` tries to carve at most this many straight routes before the bent one."""


def _routes(lobes: list[LobeState], n_kept: int, j: int, pts: np.ndarray, mains: BranchSet, step: float):
    """Routes for new lobe ``j`` clear of the kept lobes, in the order ``behind`` carves them: the straight
    ones through the fewest other new lobes (the nearest first among equals; before session 17, the nearest
    alone), then the bent one when no straight route is clear."""
    kept = kept_boxes(lobes, n_kept)  # the kept lobes alone (session 25: not a list of them packed again per lobe)
    straight = straight_routes(lobes, j, mains, box=kept)
    others = [k for k in range(n_kept, len(lobes)) if k != j]
    in_way = lobes_entered(lobes, others, [sample_polylines([r[0]], step) for r in straight])
    yield from [straight[i] for i in np.argsort(in_way, kind="stable")[:ROUTES_TRIED]]
    if not straight and (bent := bent_fallback(lobes, j, mains, pts, box=kept)) is not None:
        yield bent


def carve_route(lobes: list[LobeState], n_kept: int, j: int, route: tuple[np.ndarray, int, int],
                pts: np.ndarray, o: DecomposeOptions, step: float) -> bool:
    """Give new lobe ``j`` the branch ``route`` (segment, parent, vertex), carving it out of the other new
    lobes it enters, with the route alone as blocker, else with every other branch too; True (and
    ``lobes`` updated) when the route is then clear and no branch enters a re-carved hull it stayed out of."""
    tol = o.step / 2
    wood = sample_polylines([route[0]], step)
    lo, hi = boxes(lobes)
    meets = _boxes_meet(lo, hi, wood)
    in_way = [k for k in range(n_kept, len(lobes)) if k != j and meets[k] and enters(lobes[k], wood, (lo[k], hi[k]))]
    for with_others in (False, True):
        trial = list(lobes)
        carved = []
        pool = _others_pool(lobes, {j, *in_way} if len(in_way) == 1 else {j}, wood, step) \
            if with_others and in_way else None
        for k in in_way:
            blockers = wood if pool is None or not pool[2] else pool[0][pool[1] != k]
            if carve_lobe(trial, k, pts, blockers, o.alpha_radius):
                carved.append(k)
        trial[j] = replace(trial[j], segment=route[0], parent=route[1], parent_vertex=route[2])
        if not foreign(trial, j, route[0], tol, boxes(trial)) and not entered(lobes, trial, carved, tol):
            lobes[:] = trial
            return True
        if not carved:
            break  # no carving succeeded with the route alone: not retried with more blockers (not measured)
    return False


def _others_pool(lobes: list[LobeState], skip: set[int], wood: np.ndarray,
                 step: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """(``wood`` then the branch of every lobe not in ``skip`` resampled every ``step``, in lobe order; each
    row's lobe, -1 for ``wood``; False when no branch is in it): ``pool[owner != k]`` is the blockers
    ``carve_route`` carves lobe k with when every branch but the carved lobe's and the routed lobe's is a blocker
    too (the same rows in the same order as joining them anew for each k, and the same branches resampled;
    session 29), ``wood`` alone when there is none."""
    others = [i for i in range(len(lobes)) if i not in skip]
    parts = [wood, *(resample_step(lobes[i].segment, step) for i in others)]
    owner = np.repeat(np.array([-1, *others], np.int64), [len(p) for p in parts])
    return np.concatenate(parts), owner, bool(others)


def moved_centre(lobes: list[LobeState], j: int, pts: np.ndarray, mains: BranchSet, tries: int = 32) -> None:
    """Lobe ``j``'s centre moved to one of its own points outside every other lobe that a straight branch
    reaches clear (every (n // ``tries``)-th of its n points by distance from the old centre, nearest
    first), with that branch (in place; nothing changes when none does). The last resort for a lobe
    whose centre lies in a pocket every route to which runs through other lobes: a lobe merged from two
    clusters either side of the trunk has its mean near the trunk, among the lobes round it
    (``part_overlaps`` moves a centre the same way when it lies inside another lobe)."""
    own = pts[lobes[j].members]
    at = np.argsort(np.linalg.norm(own - lobes[j].centre, axis=1), kind="stable")
    at = at[:: max(1, len(own) // tries)]
    at = at[~inside_foreign(lobes, j, own[at])]
    own = own[at]
    found = straight_from(lobes, j, own, mains, own=(at, pts))  # the first of them a straight branch reaches
    if found is not None:
        route = found[1]
        lobes[j] = replace(lobes[j], centre=own[found[0]], segment=route[0], parent=route[1], parent_vertex=route[2])


SHALLOW = 0.001
"""How deep (0.8 m scale, working frame) ``shallow_centre``'s branch may run inside other lobes: half of
``evaluate.CROSS_TOL``, the depth at which a branch counts as crossing."""
SHALLOW_STEP = 0.0005
"""Spacing of the samples ``shallow_centre`` measures a route's depth at (a tenth of ``foreign``'s)."""


def buried(lobes: list[LobeState], j: int, pts: np.ndarray) -> bool:
    """True if every point of lobe ``j`` lies inside another lobe: ``moved_centre`` has no point to move its
    centre to, and no branch reaches lobe ``j`` without entering another lobe."""
    return bool(inside_foreign(lobes, j, pts[lobes[j].members]).all())


def depths(lobes: list[LobeState], j: int, q: np.ndarray) -> np.ndarray:
    """(M,) how deep each of ``q`` (M, 3) lies inside a lobe other than ``j`` (its largest depth; 0 outside all):
    the distance to the hull's surface (``meshdist``, numpy) of the points ``inside`` it."""
    out = np.zeros(len(q))
    lo, hi = boxes(lobes)
    for k in map(int, np.flatnonzero(_boxes_meet(lo, hi, q))):
        if k == j:
            continue
        lb = lobes[k]
        within = np.flatnonzero(inside(lb.hull_vertices, lb.hull_faces, q))
        if len(within):
            out[within] = np.maximum(out[within], surface_distances(lb.hull_vertices, lb.hull_faces, q[within]))
    return out


def shallow_centre(lobes: list[LobeState], j: int, pts: np.ndarray, mains: BranchSet, tries: int = 64) -> None:
    """Lobe ``j``'s centre moved to the own point that a straight branch from one of the ``tries`` main-branch
    vertices nearest it reaches running at most ``SHALLOW`` deep inside other lobes (its points shallowest
    first, each vertex nearest first), with that branch (in place; nothing changes when none does). The last
    resort for a lobe ``buried`` in another whose carving failed: a user's selection at the core of a small
    lobe leaves the rest round it as a shell of 10-20 points, which no carving keeps closed."""
    own = pts[lobes[j].members]
    deep = depths(lobes, j, own)
    verts, owner = main_vertices(mains)
    for i in np.argsort(deep, kind="stable"):
        if deep[i] > SHALLOW:
            return
        for v in np.argsort(np.linalg.norm(verts - own[i], axis=1), kind="stable")[:tries]:
            m = max(2, int(np.ceil(np.linalg.norm(own[i] - verts[v]) / 0.01)) + 1)  # clear.straight_fallback's
            seg = verts[v] + unit_steps(m) * (own[i] - verts[v])
            if depths(lobes, j, resample_step(seg, SHALLOW_STEP)).max() <= SHALLOW:
                lobes[j] = replace(lobes[j], centre=own[i], segment=seg, parent=int(owner[v][0]),
                                   parent_vertex=int(owner[v][1]))
                return


def entered(before: list[LobeState], after: list[LobeState], changed: list[int], tol: float) -> bool:
    """True if a branch (sampled every ``tol``) enters one of the ``changed`` lobes' hulls in ``after``
    where it stayed out of that lobe in ``before``: a hull carved again from its points keeps out of
    the new blockers only, and may fill a tunnel cut before for another branch."""
    segs = [resample_step(lb.segment, tol) for lb in after]
    which = np.concatenate([np.full(len(s), i) for i, s in enumerate(segs)])
    q = np.concatenate(segs)
    for k in changed:
        near = ((q > after[k].hull_vertices.min(axis=0)) & (q < after[k].hull_vertices.max(axis=0))).all(axis=1)
        near &= which != k
        now = set(which[near][inside(after[k].hull_vertices, after[k].hull_faces, q[near])])
        was = set(which[near][inside(before[k].hull_vertices, before[k].hull_faces, q[near])])
        if now - was:
            return True
    return False


def along(lobes: list[LobeState], n_kept: int, j: int, branch: tuple[np.ndarray, int, int], pts: np.ndarray,
          o: DecomposeOptions, step: float = 0.0025) -> bool:
    """New lobe ``j``'s branch along ``branch`` (segment, parent, vertex: the branch of the lobe it was split
    from) to one of its vertices, then straight to ``j``'s centre: the shortest such route clear of every
    other lobe, else one bent through one of ``j``'s points (``_along_bent``: or ending there, its new
    centre), else one clear of the lobes before ``n_kept`` with the new lobes it enters carved out of it
    (``carve_route``, at most ``ROUTES_TRIED``), else one bent through a waypoint in the open round ``j``'s
    centre (``_along_free``, session 25); True (``lobes`` updated in place) when one clears ``j``.

    The split lobe's branch stayed out of every other lobe and ends inside the pieces, so it reaches pieces
    that no straight, bent or routed branch from the main branches reaches clear: a pine's lobe split in 20
    (session 23's probe) left pieces whose every straight route crossed the kept lobes round the main
    branch beside them, and their routed branches ran 3 cm deep through the lobe wrapping the trunk.
    """
    tol = o.step / 2
    box = boxes(lobes)
    seg, centre = np.asarray(branch[0], np.float64), lobes[j].centre
    order, counts = _along_order(seg, centre)
    # made and tested in one compiled call up to the first clear one (session 24: 40-100 routes a piece, most
    # unused; session 28: one call, not a route and a ``foreign`` call each)
    k, resume = first_clear_along(lobes, j, seg, centre, order, counts, tol, box)
    for i in range(max(resume, 0), len(order) if resume >= 0 else 0):  # a route resampled to nothing
        if not foreign(lobes, j, _along_route(seg, centre, order[i], counts[i]), tol, box):
            k = i
            break
    if k >= 0:
        route = _along_route(seg, centre, order[k], counts[k])
        lobes[j] = replace(lobes[j], segment=route, parent=branch[1], parent_vertex=branch[2])
        return True
    bent = _along_bent(lobes, j, branch[0], pts, tol, box)
    if bent is not None:
        lobes[j] = replace(lobes[j], segment=bent[0], centre=bent[1], parent=branch[1], parent_vertex=branch[2])
        return True
    kept = kept_boxes(lobes, n_kept)  # the kept lobes alone
    clear = [_along_route(seg, centre, order[i], counts[i]) for i in _clear_along(lobes, j, seg, centre, order,
                                                                                   counts, tol, kept)]
    in_way = lobes_entered(lobes, [k for k in range(n_kept, len(lobes)) if k != j],
                           [sample_polylines([s], step) for s in clear]) if clear else np.zeros(0, int)
    if any(carve_route(lobes, n_kept, j, (clear[i], branch[1], branch[2]), pts, o, step)
           for i in np.argsort(in_way, kind="stable")[:ROUTES_TRIED]):
        return True
    free = _along_free(lobes, j, branch[0], tol, box)
    if free is not None:
        lobes[j] = replace(lobes[j], segment=free, parent=branch[1], parent_vertex=branch[2])
    return free is not None


def _clear_along(lobes: list[LobeState], j: int, seg: np.ndarray, centre: np.ndarray, order: np.ndarray,
                 counts: np.ndarray, tol: float, box: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The indices i, ascending, of the routes ``_along_route(seg, centre, order[i], counts[i])`` that ``foreign``
    finds clear against ``box``: all tested in one compiled call (``clear.first_clear_along``), any resampled to
    nothing and those after it one ``foreign`` call each (as before session 28)."""
    ok = np.zeros(len(order), bool)
    _, resume = first_clear_along(lobes, j, seg, centre, order, counts, tol, box, clear=ok)
    for i in range(max(resume, 0), len(order) if resume >= 0 else 0):
        ok[i] = not foreign(lobes, j, _along_route(seg, centre, order[i], counts[i]), tol, box)
    return np.flatnonzero(ok)


FREE_REACH = (0.025, 0.05, 0.1)
"""Distances (0.8 m scale) from a piece's centre of the waypoints ``_along_free`` bends through."""
FREE_DIRECTIONS = 32
"""Directions (a Fibonacci sphere) of ``_along_free``'s waypoints at each distance."""
FREE_MORE = 4
"""Routes ``_along_free`` checks whole after its first ``ROUTES_TRIED`` fail, each through a waypoint no route
checked before went through (session 31): the legs are tested every 5 mm from their own ends, the whole route
every ``tol`` from its start, so a leg grazing a small lobe can pass the first test and fail the second, and the
next candidates, from the split branch's next vertices to the same waypoint, graze it alike."""


def _sphere(m: int) -> np.ndarray:
    """(m, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    r, t = np.sqrt(1.0 - z * z), np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([r * np.cos(t), r * np.sin(t), z], axis=1)


def _along_free(lobes: list[LobeState], j: int, seg: np.ndarray, tol: float, box,
                step: float = 0.005) -> np.ndarray | None:
    """``along``'s last resort: ``seg`` (the split lobe's branch) to its vertex v, then to a waypoint in the
    open round lobe ``j``'s centre (``FREE_DIRECTIONS`` at each of the ``FREE_REACH`` distances, outside
    every other lobe, with a clear leg to the centre), then to the centre: the shortest clear such route, or
    None (at most ``ROUTES_TRIED`` candidates checked whole).

    Session 25 (helper-176): 6 of 783 probe splits (the leaf-on pine's lobes 3, 6 and 22 in 20) left 9
    pieces that every route along the split lobe's branch reached through a sibling piece of 6-14 points
    (too few to carve, ``carve_route``) or a kept lobe, and whose own points lay behind those siblings,
    so their routed branches ran 2.4-3.5 cm deep through the kept lobe round the trunk; each lay open on
    its far side, and a waypoint 2.5-10 cm out there was reached clear (1.4-2.0 ms of CPU a piece)."""
    centre = lobes[j].centre
    w = (centre + np.asarray(FREE_REACH)[:, None, None] * _sphere(FREE_DIRECTIONS)).reshape(-1, 3)
    w = w[~inside_foreign(lobes, j, w, box)]
    w = w[~blocked(lobes, j, w, np.broadcast_to(centre, w.shape), step, box)]
    seg = np.asarray(seg, np.float64)
    ok = _clear_prefix(lobes, j, seg, tol, box)
    if not len(w) or not ok:
        return None
    v, b = np.repeat(np.arange(ok), len(w)), np.tile(w, (ok, 1))
    arc = _arc_lengths(seg)[v]
    order = np.argsort(arc + np.linalg.norm(b - seg[v], axis=1) + np.linalg.norm(b - centre, axis=1), kind="stable")
    tried = np.zeros(len(w), bool)  # the waypoints of the routes checked whole (each failed)
    for n in range(ROUTES_TRIED + FREE_MORE):
        if n == ROUTES_TRIED:  # the rest through waypoints not tried yet
            order = order[~tried[order % len(w)]]
        k = first_clear(lobes, j, seg[v[order]], b[order], step, box, v[order])
        if k < 0:
            return None
        i = order[k]
        route = _via(seg, v[i], b[i], centre)
        if not foreign(lobes, j, route, tol, box):
            return route
        tried[i % len(w)] = True
        order = order[k + 1:]
        if n >= ROUTES_TRIED:
            order = order[order % len(w) != i % len(w)]
    return None


def _arc_lengths(seg: np.ndarray) -> np.ndarray:
    """(n,) arc length along ``seg`` (n, 3) at each of its vertices."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(seg, axis=0), axis=1))])


def _via(seg: np.ndarray, v: int, waypoint: np.ndarray, end: np.ndarray | None) -> np.ndarray:
    """``seg`` up to its vertex ``v``, then straight to ``waypoint`` and, when given, on to ``end`` (every 1 cm)."""
    route = np.vstack([seg[:v], resample_step(np.stack([seg[v], waypoint]), 0.01)])
    return route if end is None else np.vstack([route, resample_step(np.stack([waypoint, end]), 0.01)[1:]])


def _clear_prefix(lobes: list[LobeState], j: int, seg: np.ndarray, tol: float, box) -> int:
    """How many of ``seg``'s first vertices stay out of every lobe but ``j`` (each prefix tested in turn up to the
    first that does not, in one compiled call: ``clear.clear_prefix_length``)."""
    ok, resume = clear_prefix_length(lobes, j, seg, tol, box)
    if resume >= 0:  # a prefix resampled to nothing: the rest one ``foreign`` call each, as before session 28
        while ok < len(seg) and not foreign(lobes, j, seg[: ok + 1], tol, box):
            ok += 1
    return ok


def _along_bent(lobes: list[LobeState], j: int, seg: np.ndarray, pts: np.ndarray, tol: float, box,
                waypoints: int = 32, step: float = 0.005) -> tuple[np.ndarray, np.ndarray] | None:
    """(route, centre) for lobe ``j`` along ``seg`` to its vertex v, then to one of every (n // ``waypoints``)-th
    of the lobe's n points outside other lobes, then to its centre (the shortest clear such route); else the
    shortest clear route to one of those points, which becomes the centre (as ``moved_centre`` does); None if
    no route is clear."""
    centre = lobes[j].centre
    own = pts[lobes[j].members]
    w = own[:: max(1, len(own) // waypoints)]
    w = w[~inside_foreign(lobes, j, w, box)]
    seg = np.asarray(seg, np.float64)
    ok = _clear_prefix(lobes, j, seg, tol, box)
    if not len(w) or not ok:
        return None
    v = np.repeat(np.arange(ok), len(w))
    a, b = seg[v], np.tile(w, (ok, 1))
    first = ~blocked(lobes, j, a, b, step, box)
    arc = _arc_lengths(seg)[v]
    length = np.where(first, arc + np.linalg.norm(b - a, axis=1), np.inf)
    last = np.tile(~blocked(lobes, j, w, np.broadcast_to(centre, w.shape), step, box), ok)
    leg = np.tile(np.linalg.norm(w - centre, axis=1), ok)
    for total, bend in ((np.where(last, length + leg, np.inf), True), (length, False)):
        k = int(np.argmin(total))
        if not np.isfinite(total[k]):
            continue
        route = _via(seg, v[k], b[k], centre if bend else None)
        if not foreign(lobes, j, route, tol, box):
            return route, centre if bend else b[k]
    return None


def _along_routes(branch: tuple[np.ndarray, int, int], centre: np.ndarray) -> list[np.ndarray]:
    """Every route ``along`` tries, shortest first: ``branch``'s segment up to its vertex v, then every
    <= 1 cm straight to ``centre``, for each v."""
    return list(_along_route_iter(branch, centre))


def _along_route_iter(branch: tuple[np.ndarray, int, int], centre: np.ndarray) -> Iterator[np.ndarray]:
    """``_along_routes`` one by one, shortest first."""
    seg = np.asarray(branch[0], np.float64)
    for v, m in zip(*_along_order(seg, centre)):
        yield _along_route(seg, centre, v, m)


def _along_route(seg: np.ndarray, centre: np.ndarray, v: int, m: int) -> np.ndarray:
    """``seg`` (float64) up to its vertex ``v``, then ``m`` points evenly from ``seg[v]`` to ``centre``."""
    return np.vstack([seg[:v], seg[v] + unit_steps(m) * (centre - seg[v])])


CEIL_MARGIN = 1e-6
"""``_along_order`` computes a count again with ``np.linalg.norm`` when gap / 1 cm lies this close (relative) to
an integer: its vectorised root of the summed squares differs from ``np.linalg.norm``'s by a few ulps at most."""


def _along_order(seg: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order, counts): ``seg``'s (float64) vertices v in the order ``_along_routes`` makes their routes (shortest
    first), and each route's points from v to ``centre``, max(2, ceil(|centre - v| / 1 cm) + 1), as
    ``np.linalg.norm`` of each gap gives them (the gaps are the distances the order is made of, computed again
    one by one where the rounding could move the ceiling)."""
    if len(seg) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(seg, axis=0), axis=1))])
    dist = np.linalg.norm(seg - centre, axis=1)
    order = np.argsort(arc + dist, kind="stable")
    x = dist[order] / 0.01
    for i in np.flatnonzero(np.abs(x - np.rint(x)) <= CEIL_MARGIN * (1.0 + x)):
        x[i] = float(np.linalg.norm(centre - seg[order[i]])) / 0.01
    x = np.ceil(x)
    if not np.isfinite(x).all():  # int() raises on it, as it did route by route
        return order, np.array([max(2, int(c) + 1) for c in x], np.int64)
    return order, np.maximum(2, x.astype(np.int64) + 1)
