"""The particle loop of the harmonic model: all active buds of a step advance together (numpy).

``grow_particles`` runs the growth steps and returns ``Particles``: one record per emitted particle in
birth order (parents first), with the bud orientation of the internode that ends at it. Positions and
radii depend on the final age of every internode (secondary growth), so they are computed at the end
(``Particles.positions``, ``Particles.radii``), one vectorised pass per growth step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import quat
from .species import LevelParams, SpeciesParams

DEG = np.pi / 180.0


@dataclass(frozen=True)
class Particles:
    """Every particle of a grown tree, in birth order (a parent before its children)."""

    q: np.ndarray
    """(N, 4) float64 wxyz: bud frame of the internode ending at the particle (local +Z = its direction)."""
    parent: np.ndarray
    """(N,) int32: parent particle, -1 for the root (particle 0)."""
    level: np.ndarray
    """(N,) int32: hierarchy level (0 = trunk)."""
    branch: np.ndarray
    """(N,) int32: branch id (0 = trunk)."""
    birth: np.ndarray
    """(N,) int32: growth step at which the particle was emitted."""
    step_offsets: np.ndarray
    """(S + 1,) int64: particles of step s are ``step_offsets[s]:step_offsets[s + 1]``."""
    leaf_node: np.ndarray
    """(M,) int32: the particle each leaf hangs on."""
    leaf_theta: np.ndarray
    """(M, 3) float64: leaf orientation theta (radians, intrinsic XYZ Euler angles)."""
    leaf_size: np.ndarray
    """(M,) float64, metres: leaf length."""
    params: SpeciesParams
    """The individual's parameters."""

    def ages(self) -> np.ndarray:
        """(N,) age in steps of every internode at the end of growth (0 for the newest)."""
        return (len(self.step_offsets) - 2 - self.birth).astype(np.float64)

    def positions(self) -> np.ndarray:
        """(N, 3) metres: internodes of length Z s_i min(1 + E a, E_max) at age a, chained from the root."""
        p = self.params
        scale = np.array([lv.segment_scale for lv in p.levels])[self.level]
        length = p.segment_size * scale * np.minimum(1.0 + p.elongation * self.ages(), p.elongation_max)
        vec = quat.rotate(self.q, quat.EZ) * length[:, None]
        pos = np.zeros((len(self.parent), 3))
        off = self.step_offsets
        for s in range(1, len(off) - 1):
            sl = slice(off[s], off[s + 1])
            pos[sl] = pos[self.parent[sl]] + vec[sl]
        return pos

    def radii(self) -> np.ndarray:
        """(N,) metres: max(secondary growth TP_i Z (a + 1), pipe model of the children)."""
        p = self.params
        taper = np.array([lv.taper for lv in p.levels])[self.level]
        r_age = taper * p.segment_size * (self.ages() + 1.0)
        e = p.pipe_exponent
        acc = np.zeros(len(self.parent))
        r = np.zeros(len(self.parent))
        off = self.step_offsets
        for s in range(len(off) - 2, -1, -1):
            lo, hi = off[s], off[s + 1]
            r[lo:hi] = np.maximum(r_age[lo:hi], acc[lo:hi] ** (1.0 / e))
            if lo > 0:
                acc[:lo] += np.bincount(self.parent[lo:hi], weights=r[lo:hi] ** e, minlength=lo)
        return r


class _Tables:
    """Per-level parameters as arrays indexed by level (radians, steps)."""

    def __init__(self, p: SpeciesParams) -> None:
        lv = p.levels

        def arr(get: Callable[[LevelParams], Any], dtype: Any = np.float64) -> np.ndarray:
            return np.array([get(x) for x in lv], dtype=dtype)

        self.n_levels = len(lv)
        self.span_start = arr(lambda x: x.span_spacing)
        self.span_angle = arr(lambda x: x.span_angle) * DEG
        self.wander_spacing = arr(lambda x: x.wander_spacing, np.int64)
        self.wander_amp = arr(lambda x: x.wander_amplitude) * DEG
        self.wander_noise = arr(lambda x: x.wander_noise)
        self.harm_f = arr(lambda x: x.harmonic_frequency)
        self.harm_a = arr(lambda x: x.harmonic_amplitude) * DEG
        self.node_spacing = arr(lambda x: x.node_spacing, np.int64)
        self.node_start = arr(lambda x: max(x.node_start, 1), np.int64)
        self.node_prob = arr(lambda x: x.node_probability)
        self.buds = arr(lambda x: x.buds_per_node, np.int64)
        self.twist = arr(lambda x: x.twist) * DEG
        self.length = arr(lambda x: x.length)
        self.prob = arr(lambda x: x.probability)
        self.angle = arr(lambda x: x.angle) * DEG
        self.leaf_spacing = arr(lambda x: x.leaf.spacing, np.int64)
        self.leaf_prob = arr(lambda x: x.leaf.probability)
        self.leaf_scale = arr(lambda x: x.leaf.scale)
        self.leaf_min = arr(lambda x: x.leaf.angle_min) * DEG
        self.leaf_max = arr(lambda x: x.leaf.angle_max) * DEG


@dataclass
class _Buds:
    """The active apical buds (M of them)."""

    q: np.ndarray  # (M, 4) wxyz bud frames
    last: np.ndarray  # (M,) int64 last particle emitted (the parent of the next)
    level: np.ndarray  # (M,) int64
    branch: np.ndarray  # (M,) int64
    age: np.ndarray  # (M,) int64 internodes grown on this branch
    term: np.ndarray  # (M,) int64 terminal age
    phase: np.ndarray  # (M, K_h) harmonic phases (radians)

    def take(self, keep: np.ndarray) -> _Buds:
        return _Buds(*(getattr(self, f)[keep] for f in self.__dataclass_fields__))

    @staticmethod
    def concat(a: _Buds, b: _Buds) -> _Buds:
        return _Buds(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in a.__dataclass_fields__))


def _trunk(p: SpeciesParams, t: _Tables, rng: np.random.Generator) -> _Buds:
    """The single trunk bud, leaning up to the level-0 angle from vertical in a random direction."""
    lean = rng.uniform(0.0, t.angle[0])
    az = rng.uniform(0.0, 2.0 * np.pi)
    d = np.array([[np.sin(lean) * np.cos(az), np.sin(lean) * np.sin(az), np.cos(lean)]])
    return _Buds(
        q=quat.level_frame(d, np.array([az])), last=np.array([-1]), level=np.array([0]),
        branch=np.array([0]), age=np.array([0]), term=np.array([int(t.length[0])]),
        phase=rng.uniform(0.0, 2.0 * np.pi, (1, t.harm_f.shape[1])),
    )


def _turn(b: _Buds, t: _Tables, rng: np.random.Generator) -> np.ndarray:
    """Equation 1: B R W H for every bud (M, 4), at the buds' current ages."""
    lvl, age = b.level, b.age
    k = (t.span_start[lvl] <= age[:, None]).sum(axis=1) - 1
    phi = np.where(k >= 0, t.span_angle[lvl, np.maximum(k, 0)], 0.0)
    q = quat.mul(b.q, quat.axis_angle(quat.EX, phi))  # R_i: span arc, positive = up
    ws = t.wander_spacing[lvl]
    on = (ws > 0) & (age[:, None] > 0) & (age[:, None] % np.maximum(ws, 1) == 0)
    if on.any():  # W_i: turn by WA_k about a random axis across the bud every WS_k internodes
        beta = rng.uniform(0.0, 2.0 * np.pi, on.shape)
        u = rng.uniform(-1.0, 1.0, on.shape)
        ang = np.where(on, t.wander_amp[lvl] * (1.0 + t.wander_noise[lvl][:, None] * u), 0.0)
        axes = np.stack([np.cos(beta), np.sin(beta), np.zeros_like(beta)], axis=-1)
        for j in range(on.shape[1]):
            q = quat.mul(q, quat.axis_angle(axes[:, j], ang[:, j]))
    amp = t.harm_a[lvl]
    if np.any(amp != 0):  # H_i: sum of sin(t f_k + phase) a_k, even k sideways, odd k up/down
        ang = np.sin(age[:, None] * t.harm_f[lvl] + b.phase) * amp
        for j in range(amp.shape[1]):
            q = quat.mul(q, quat.axis_angle(quat.EY if j % 2 == 0 else quat.EX, ang[:, j]))
    return quat.normalize(q)


def _spawn(b: _Buds, idx: np.ndarray, t: _Tables, p: SpeciesParams, rng: np.random.Generator,
           next_branch: int) -> _Buds:
    """New lateral buds from the nodes among the buds that just emitted particles ``idx`` (M,)."""
    lvl, age = b.level, b.age
    ns, start = t.node_spacing[lvl], t.node_start[lvl]
    node = (lvl < t.n_levels - 1) & (age >= start) & ((age - start) % ns == 0)
    node &= rng.random(len(lvl)) < t.node_prob[lvl]
    nb = int(t.buds[lvl[node]].max()) if node.any() else 0
    src = np.flatnonzero(node)
    child = np.minimum(lvl[src] + 1, t.n_levels - 1)
    j = np.arange(nb)
    az = age[src, None] * t.twist[lvl[src], None] + 2.0 * np.pi * j / np.maximum(t.buds[lvl[src], None], 1)
    az = az + rng.uniform(-0.15, 0.15, az.shape)
    ok = (j < t.buds[lvl[src], None]) & (rng.random(az.shape) < t.prob[child, None])
    s_i, j_i = np.nonzero(ok)
    src, child, az = src[s_i], child[s_i], az[s_i, j_i]
    a = t.angle[child]
    local = np.stack([np.sin(a) * np.cos(az), np.sin(a) * np.sin(az), np.cos(a)], axis=-1)
    d = quat.rotate(b.q[src], local)
    term = t.length[child] * (1.0 + p.variation * rng.uniform(-1.0, 1.0, len(src)))
    return _Buds(
        q=quat.level_frame(d, az), last=idx[src], level=child,
        branch=next_branch + np.arange(len(src)), age=np.zeros(len(src), np.int64),
        term=np.maximum(np.rint(term), 1).astype(np.int64),
        phase=rng.uniform(0.0, 2.0 * np.pi, (len(src), t.harm_f.shape[1])),
    )


def _leaves(b: _Buds, idx: np.ndarray, t: _Tables, p: SpeciesParams, rng: np.random.Generator):
    """(particle (K,), theta (K, 3), size (K,)) of the leaves on the particles just emitted."""
    ls = t.leaf_spacing[b.level]
    site = (ls > 0) & (b.age > 0) & (b.age % np.maximum(ls, 1) == 0)
    site &= rng.random(len(ls)) < t.leaf_prob[b.level]
    lv = b.level[site]
    theta = rng.uniform(t.leaf_min[lv], t.leaf_max[lv])
    size = t.leaf_scale[lv] * (1.0 + p.variation * rng.uniform(-1.0, 1.0, len(lv)))
    return idx[site], theta, size


def grow_particles(p: SpeciesParams, rng: np.random.Generator, steps: int) -> Particles:
    """Run ``steps`` growth steps of species ``p`` (one individual) and return every particle."""
    t = _Tables(p)
    buds = _trunk(p, t, rng)
    rec: dict[str, list[np.ndarray]] = {k: [] for k in ("q", "parent", "level", "branch", "birth")}
    leaves: list[tuple] = []
    offsets, n, next_branch = [0], 0, 1
    for s in range(steps):
        m = len(buds.level)
        if m == 0:
            break
        idx = n + np.arange(m)
        for key, val in (("q", buds.q), ("parent", buds.last), ("level", buds.level),
                         ("branch", buds.branch), ("birth", np.full(m, s))):
            rec[key].append(val)
        n += m
        offsets.append(n)
        leaves.append(_leaves(buds, idx, t, p, rng))
        new = _spawn(buds, idx, t, p, rng, next_branch) if n < p.max_particles else None
        buds.q, buds.last = _turn(buds, t, rng), idx
        buds.age = buds.age + 1
        buds = buds.take(buds.age < buds.term)
        if new is not None and len(new.level):
            next_branch += len(new.level)
            buds = _Buds.concat(buds, new)
    i32 = np.int32
    return Particles(
        q=np.concatenate(rec["q"]), parent=np.concatenate(rec["parent"]).astype(i32),
        level=np.concatenate(rec["level"]).astype(i32), branch=np.concatenate(rec["branch"]).astype(i32),
        birth=np.concatenate(rec["birth"]).astype(i32), step_offsets=np.array(offsets, np.int64),
        leaf_node=np.concatenate([x[0] for x in leaves]).astype(i32),
        leaf_theta=np.concatenate([x[1] for x in leaves]).reshape(-1, 3),
        leaf_size=np.concatenate([x[2] for x in leaves]), params=p,
    )
