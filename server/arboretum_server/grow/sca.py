"""Space colonization inside lobes (VRTree section 3.5, Eq. 2; Runions et al. 2007), all lobes at once.

Each iteration, for every growable node n with a non-empty set S(n) of live attraction points:

    V = V_s + α V_g + β V_att,   child = n + D V / |V|

* V_s: unit tangent of the lobe's secondary branch at its bud (per lobe, as in the paper);
* V_g = (0, 0, -1), gravity in our Z-up frame;
* V_att = Σ_{p ∈ S(n)} (p - n) / |p - n|, the *sum* of unit vectors (Runions' colonization vector,
  not its mean). Its length is the number of points pulling the node the same way, so while a node
  has more than about α/β ≈ 5 aligned points ahead of it attraction outweighs gravity and the twig
  fills the lobe; as the points are consumed, heading and gravity take over and the last twigs droop —
  the "downward growth of twigs" the paper attributes to V_g. With the mean instead of the sum,
  α = 1.6 against β = 0.3 would make every twig fall out of its lobe.

S(n) is the set of live points whose nearest growable node is n within the influence distance d_i,
except for a bud inside its hull that owns no point: it is pulled by every live point of its lobe (the
paper's "directions from the bud to each vertex of the lobe"). Two rules of ours keep twigs growing in
lobes that are not convex (alpha shapes, and lobes carved round the trunk):

* a node outside its hull (a bud short of its lobe, then the chain growing in from it) heads straight
  for the nearest live point of its lobe, one step D at a time. Pulled by the whole lobe instead, a
  bud beside a lobe that wraps round it felt pulls that cancel, and the lobe stayed bare;
* a node inside its hull whose Eq. 2 step would leave the hull (its points lie across a concavity)
  steps toward its nearest own point instead of growing a dead-end twig outside.

A point dies when any node comes within d_k. Only nodes inside their lobe hull (and approach chains)
may spawn, so every twig node lies inside its hull or within one step D of it. A proposed child whose
cell (size ``min_spacing`` × D) already holds a node is refused and its parent stops growing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import KDTree

from arboretum_library.progress import ProgressFn, no_progress

from .attraction import Attraction
from .hulls import inside
from .options import GRAVITY, GrowOptions


@dataclass(frozen=True, eq=False)
class Colonized:
    """Twig nodes grown by space colonization. Buds come first (indices 0..B-1)."""

    positions: np.ndarray
    """(N, 3) float64, metres: buds, then grown nodes in creation order."""
    parents: np.ndarray
    """(N,) int64: parent node index (< own index); -1 for buds."""
    lobe: np.ndarray
    """(N,) int64: lobe of each node."""
    approach: np.ndarray
    """(N,) bool: node grew outside its hull on the way in from a bud outside it."""
    iterations: int
    """Colonization iterations run."""
    points_left: int
    """Attraction points still alive at the end."""


class _State:
    """Growing arrays of one colonization run."""

    def __init__(self, buds: np.ndarray, bud_lobe: np.ndarray, bud_inside: np.ndarray, n_points: int):
        self.pos = np.asarray(buds, np.float64).reshape(-1, 3)
        self.parent = np.full(len(self.pos), -1, np.int64)
        self.lobe = np.asarray(bud_lobe, np.int64)
        self.approach = ~np.asarray(bud_inside, bool)
        self.whole_lobe = self.approach.copy()
        self.growable = np.ones(len(self.pos), bool)
        self.alive = np.ones(n_points, bool)
        self.best_d = np.full(n_points, np.inf)
        self.best_node = np.full(n_points, -1, np.int64)
        self.cells = np.zeros(0, np.int64)
        self.sep = 1.0
        self.kill = np.zeros(0)


def colonize(att: Attraction, buds: np.ndarray, bud_lobe: np.ndarray, headings: np.ndarray,
             opts: GrowOptions, step: float, progress: ProgressFn = no_progress) -> Colonized:
    """Grow twigs from ``buds`` (B, 3) of lobes ``bud_lobe`` (B,) with lobe headings V_s (L, 3)."""
    bud_inside = inside(att.index, buds, bud_lobe)
    st = _State(buds, bud_lobe, bud_inside, len(att.points))
    st.cells = np.unique(_cells(st.pos, step * max(opts.min_spacing, 1e-6)))
    sep = float(np.ptp(att.points, axis=0).max() if len(att.points) else 1.0) * 10 + 10 * step
    st.sep = sep
    dens = np.array([max(opts.lobe_multiplier(i), 1e-3) for i in range(len(headings))])
    st.kill = opts.kill / np.cbrt(np.maximum(dens, 0.125))  # denser twigs: points die closer to nodes
    unlimited = opts.influence is None and len(att.points)
    ptree = KDTree(_embed(att.points, att.lobe, sep)) if unlimited else None
    new = np.arange(len(st.pos))
    it = 0
    for it in range(1, opts.max_iterations + 1):
        if not st.alive.any() or not len(new):
            it -= 1
            break
        _absorb(st, att, ptree, new, opts, step, sep)
        if it == 1:  # a bud inside its hull with no point within d_i is pulled by its whole lobe
            owned = np.bincount(st.best_node[st.alive & (st.best_node >= 0)], minlength=len(st.pos))
            st.whole_lobe |= owned == 0
        new = _grow(st, att, headings, opts, step)
        progress(it, opts.max_iterations, f"colonizing ({len(st.pos)} nodes)")
    return Colonized(st.pos, st.parent, st.lobe, st.approach, it, int(st.alive.sum()))


def _embed(points: np.ndarray, lobe: np.ndarray, sep: float) -> np.ndarray:
    """(N, 4): points with their lobe as a far-apart 4th coordinate (queries never cross lobes)."""
    return np.c_[points, lobe * sep]


def _cells(pos: np.ndarray, size: float) -> np.ndarray:
    """(N,) int64 keys of the cubic cells of side ``size`` holding ``pos`` (N, 3)."""
    c = np.floor(pos / size).astype(np.int64) + (1 << 20)
    c = np.clip(c, 0, (1 << 21) - 1)
    return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]


def _absorb(st: _State, att: Attraction, ptree: KDTree | None, new: np.ndarray, opts: GrowOptions,
            step: float, sep: float) -> None:
    """Kill points near the ``new`` nodes and let them claim points they are nearest to."""
    if ptree is not None:  # unlimited influence: exact nearest growable node for every live point
        _kill_near(st, att, ptree, new, step, sep)
        _reassign_all(st, att, sep, np.inf)
        return
    reach = step * (opts.influence if opts.influence is not None else np.inf)
    busy = np.zeros(len(st.kill), bool)
    busy[st.lobe[new]] = True
    live = np.flatnonzero(st.alive & busy[att.lobe])  # only lobes that grew can kill or claim
    ntree = KDTree(_embed(st.pos[new], st.lobe[new], sep))
    d, k = ntree.query(_embed(att.points[live], att.lobe[live], sep),
                       distance_upper_bound=max(reach, opts.kill * step * 2))
    d, k = np.asarray(d), np.asarray(k)
    hit = np.isfinite(d)
    live, d, node = live[hit], d[hit], new[k[hit]]
    st.alive[live[d < st.kill[att.lobe[live]] * step]] = False
    claim = st.growable[node] & ~st.whole_lobe[node] & (d < reach) & (d < st.best_d[live])
    st.best_d[live[claim]] = d[claim]
    st.best_node[live[claim]] = node[claim]


def _kill_near(st: _State, att: Attraction, ptree: KDTree, new: np.ndarray, step: float,
               sep: float) -> None:
    """Kill the live points within their lobe's kill distance of the ``new`` nodes."""
    ntree = KDTree(_embed(st.pos[new], st.lobe[new], sep))
    pairs = ntree.sparse_distance_matrix(ptree, float(st.kill.max()) * step, output_type="ndarray")
    j = pairs["j"]
    st.alive[j[pairs["v"] < st.kill[att.lobe[j]] * step]] = False


def _reassign_all(st: _State, att: Attraction, sep: float, reach: float) -> None:
    """Give every live point its nearest growable (non-bud) node within ``reach`` (slow path)."""
    cand = np.flatnonzero(st.growable & ~st.whole_lobe)
    live = np.flatnonzero(st.alive)
    st.best_node[:] = -1
    st.best_d[:] = np.inf
    if not len(cand) or not len(live):
        return
    tree = KDTree(_embed(st.pos[cand], st.lobe[cand], sep))
    d, k = tree.query(_embed(att.points[live], att.lobe[live], sep), distance_upper_bound=reach)
    d, k = np.asarray(d), np.asarray(k)
    ok = np.isfinite(d)
    st.best_d[live[ok]] = d[ok]
    st.best_node[live[ok]] = cand[k[ok]]


def _pull(st: _State, att: Attraction) -> tuple[np.ndarray, ...]:
    """Active nodes (K,), their V_att sums (K, 3) (nearest-node sets, and whole lobes for buds inside
    their hull) and aims (K, 3): for nodes outside their hull the nearest live point of their lobe,
    NaN for the others.

    Also returns the (point, node) pairs of the nearest-node sets, (P,) each.
    """
    n = len(st.pos)
    live = np.flatnonzero(st.alive & (st.best_node >= 0))
    node = st.best_node[live]
    live, node = live[st.growable[node]], node[st.growable[node]]
    u = _unit(att.points[live] - st.pos[node])
    vatt = np.stack([np.bincount(node, u[:, k], minlength=n) for k in range(3)], axis=1).astype(np.float64)
    count = np.bincount(node, minlength=n)
    whole = np.flatnonzero(st.whole_lobe & st.growable & ~st.approach)
    if len(whole):
        lo, hi = att.starts[st.lobe[whole]], att.starts[st.lobe[whole] + 1]
        reps = hi - lo
        who = np.repeat(whole, reps)
        pt = np.repeat(lo, reps) + np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
        keep = st.alive[pt]
        who, pt = who[keep], pt[keep]
        u = _unit(att.points[pt] - st.pos[who])
        for k in range(3):
            vatt[:, k] += np.bincount(who, u[:, k], minlength=n)
        count += np.bincount(who, minlength=n)
    aim = np.full((n, 3), np.nan)
    outside = np.flatnonzero(st.approach & st.growable)
    aim[outside] = _nearest_live(st, att, outside)
    count[outside[np.isfinite(aim[outside, 0])]] += 1
    active = np.flatnonzero((count > 0) & st.growable)
    return active, vatt[active], aim[active], live, node


def _nearest_live(st: _State, att: Attraction, nodes: np.ndarray) -> np.ndarray:
    """(K, 3): the nearest live attraction point of each node's lobe (NaN where none is left)."""
    out = np.full((len(nodes), 3), np.nan)
    for i, n in enumerate(nodes):
        lo, hi = att.starts[st.lobe[n]], att.starts[st.lobe[n] + 1]
        pts = att.points[lo:hi][st.alive[lo:hi]]
        if len(pts):
            out[i] = pts[np.argmin(((pts - st.pos[n]) ** 2).sum(axis=1))]
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def _approaches(st: _State, att: Attraction, active: np.ndarray, v: np.ndarray, pts: np.ndarray,
                owner: np.ndarray, step: float) -> np.ndarray:
    """(K,) bool: the step D·v of each active node brings it closer to at least one of its points.

    |n + D v - p| < |n - p|  <=>  v·(p - n) > D / 2. A node pulled only by points it cannot get
    nearer to (gravity outweighs a weak pull from above) stops instead of drooping away from them.
    """
    slot = np.full(len(st.pos), -1, np.int64)
    slot[active] = np.arange(len(active))
    k = slot[owner]
    ok = k >= 0
    score = ((att.points[pts[ok]] - st.pos[owner[ok]]) * v[k[ok]]).sum(1)
    best = np.full(len(active), -np.inf)
    np.maximum.at(best, k[ok], score)
    return best > step / 2


def _nearest_own(st: _State, att: Attraction, active: np.ndarray, sel: np.ndarray, pts: np.ndarray,
                 owner: np.ndarray) -> np.ndarray:
    """(S, 3): for the active nodes ``active[sel]``, the nearest point of their own set S(n)."""
    slot = np.full(len(st.pos), -1, np.int64)
    slot[active[sel]] = np.arange(int(sel.sum()))
    k = slot[owner]
    ok = k >= 0
    d = ((att.points[pts[ok]] - st.pos[owner[ok]]) ** 2).sum(1)
    order = np.lexsort((d, k[ok]))
    kk = k[ok][order]
    first = order[np.r_[True, kk[1:] != kk[:-1]]] if len(order) else order
    out = np.full((int(sel.sum()), 3), np.nan)
    out[k[ok][first]] = att.points[pts[ok][first]]
    return out


def _step_toward(pos: np.ndarray, aim: np.ndarray, v: np.ndarray, child: np.ndarray, step: float) -> None:
    """Where ``aim`` (K, 3) is finite, turn ``v`` to it and move ``child`` one step D that way."""
    toward = np.isfinite(aim[:, 0])
    v[toward] = _unit(aim[toward] - pos[toward])
    child[toward] = pos[toward] + step * v[toward]


def _propose(st: _State, att: Attraction, headings: np.ndarray, opts: GrowOptions, step: float,
             active: np.ndarray, vatt: np.ndarray, aim: np.ndarray, pts: np.ndarray,
             owner: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direction (K, 3), child position (K, 3) and whether the child lies in its hull (K,) per active
    node: Eq. 2, or straight for ``aim`` (K, 3) where it is finite or where Eq. 2 leaves the hull."""
    v = _unit(headings[st.lobe[active]] + opts.alpha * np.asarray(GRAVITY) + opts.beta * vatt)
    child = st.pos[active] + step * v
    is_in = inside(att.index, child, st.lobe[active])
    out = ~is_in & ~st.whole_lobe[active]
    aim[out] = _nearest_own(st, att, active, out, pts, owner)
    moved = np.isfinite(aim[:, 0])
    _step_toward(st.pos[active], aim, v, child, step)
    is_in[moved] = inside(att.index, child[moved], st.lobe[active[moved]])
    return v, child, is_in


def _grow(st: _State, att: Attraction, headings: np.ndarray, opts: GrowOptions, step: float) -> np.ndarray:
    """Propose one child per active node (Eq. 2); returns the indices of the accepted children."""
    active, vatt, aim, pts, owner = _pull(st, att)
    if not len(active):
        return np.zeros(0, np.int64)
    v, child, is_in = _propose(st, att, headings, opts, step, active, vatt, aim, pts, owner)
    keys = _cells(child, step * max(opts.min_spacing, 1e-6))
    _, first = np.unique(keys, return_index=True)
    fresh = np.zeros(len(child), bool)
    fresh[first] = True
    pos = np.minimum(np.searchsorted(st.cells, keys), max(len(st.cells) - 1, 0))
    fresh &= st.cells[pos] != keys if len(st.cells) else True
    fresh &= _approaches(st, att, active, v, pts, owner, step) | st.whole_lobe[active]
    st.growable[active[~fresh]] = False
    st.growable[active[st.whole_lobe[active]]] = False  # an approaching node spawns once
    blocked = st.best_node >= 0
    blocked[blocked] = ~st.growable[st.best_node[blocked]]
    st.best_node[blocked], st.best_d[blocked] = -1, np.inf
    parent, child, keys, is_in = active[fresh], child[fresh], keys[fresh], is_in[fresh]
    lobe = st.lobe[parent]
    approach = st.approach[parent] & ~is_in
    keys = np.sort(keys)
    st.cells = np.insert(st.cells, np.searchsorted(st.cells, keys), keys)
    first_new = len(st.pos)
    st.pos = np.concatenate([st.pos, child])
    st.parent = np.concatenate([st.parent, parent])
    st.lobe = np.concatenate([st.lobe, lobe])
    st.approach = np.concatenate([st.approach, approach])
    st.whole_lobe = np.concatenate([st.whole_lobe, approach])
    st.growable = np.concatenate([st.growable, is_in | approach])
    if blocked.any():
        _rescue(st, att, np.flatnonzero(blocked & st.alive), opts, step, st.sep)
    return np.arange(first_new, len(st.pos))


def _rescue(st: _State, att: Attraction, pts: np.ndarray, opts: GrowOptions, step: float,
            sep: float) -> None:
    """Points whose node stopped: find their nearest other growable node within d_i."""
    lobes = np.zeros(int(st.lobe.max()) + 1, bool)
    lobes[att.lobe[pts]] = True
    cand = np.flatnonzero(st.growable & ~st.whole_lobe & lobes[st.lobe])
    if not len(cand) or not len(pts):
        return
    reach = step * (opts.influence if opts.influence is not None else 1e9)
    tree = KDTree(_embed(st.pos[cand], st.lobe[cand], sep))
    d, k = tree.query(_embed(att.points[pts], att.lobe[pts], sep), distance_upper_bound=reach)
    d, k = np.asarray(d), np.asarray(k)
    ok = np.isfinite(d)
    st.best_d[pts[ok]] = d[ok]
    st.best_node[pts[ok]] = cand[k[ok]]
