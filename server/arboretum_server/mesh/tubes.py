"""Generalized cylinders: every chain swept at once with parallel-transport frames, capped, with bark UVs.

Frames travel along each chain by the double-reflection method (Wang et al. 2008), one vectorised step
per chain position for all chains together. Tangents at inner vertices are central differences, so the
ring at a bend lies in its bisecting plane, stretched across the bend by the miter factor
1/cos(turn/2) (at most ``MAX_MITER``) so the tube does not pinch (smooth joints). Each chain's tube is closed by a fan cap at
each end and is watertight once its seam vertices (u = 0 and u = 1 of a ring) are welded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .chains import Chains


@dataclass(frozen=True, eq=False)
class Tubes:
    """Tube meshes of all chains in one vertex/face array."""

    positions: np.ndarray
    """(V, 3) float64, metres, world frame."""
    normals: np.ndarray
    """(V, 3) float64 unit."""
    uv: np.ndarray
    """(V, 2) float64: u around (0..1, seam duplicated), v along (bark repeats per circumference)."""
    faces: np.ndarray
    """(F, 3) int64, outward."""
    face_chain: np.ndarray
    """(F,) int64: chain of each face."""


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


MAX_MITER = 2.0
"""Largest stretch of a ring across a bend (1 / cos of half the turn; reached at a 120° turn)."""


def _tangents(p: np.ndarray, chains: Chains) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit tangents (M, 3): central differences inside a chain, one-sided at its ends; unit bend
    directions (M, 3) (in the ring's plane, zero where straight) and miter factors (M,) >= 1."""
    m = len(p)
    first = np.zeros(m, bool)
    first[chains.starts[:-1]] = True
    last = np.zeros(m, bool)
    last[chains.starts[1:] - 1] = True
    nxt = np.where(last, np.arange(m), np.minimum(np.arange(m) + 1, m - 1))
    prv = np.where(first, np.arange(m), np.maximum(np.arange(m) - 1, 0))
    out, into = _unit(p[nxt] - p), _unit(p - p[prv])
    t = out + into
    hairpin = (t * t).sum(1) < 1e-12  # a reversal: fall back to the incoming (or outgoing) direction
    t[hairpin] = np.where((into[hairpin] ** 2).sum(1, keepdims=True) > 0.5, into[hairpin], out[hairpin])
    t = _unit(t)
    bend = out - into
    bend -= (bend * t).sum(1, keepdims=True) * t
    straight = (bend * bend).sum(1) < 1e-18
    bend = np.where(straight[:, None], 0.0, _unit(bend))
    cos_half = np.where(first | last, 1.0, (t * into).sum(1))
    return t, bend, 1.0 / np.clip(cos_half, 1.0 / MAX_MITER, 1.0)


def _frames(p: np.ndarray, t: np.ndarray, chains: Chains) -> np.ndarray:
    """(M, 3) unit normals transported along each chain by double reflection."""
    starts, counts = chains.starts[:-1], np.diff(chains.starts)
    n = np.zeros_like(p)
    t0 = t[starts]
    ref = np.where(np.abs(t0[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    n[starts] = _unit(np.cross(t0, ref))
    for k in range(1, int(counts.max()) if len(counts) else 0):
        i = starts[counts > k] + k
        v1 = p[i] - p[i - 1]
        c1 = np.maximum((v1 * v1).sum(1, keepdims=True), 1e-30)
        r_l = n[i - 1] - (2 / c1) * (v1 * n[i - 1]).sum(1, keepdims=True) * v1
        t_l = t[i - 1] - (2 / c1) * (v1 * t[i - 1]).sum(1, keepdims=True) * v1
        v2 = t[i] - t_l
        c2 = np.maximum((v2 * v2).sum(1, keepdims=True), 1e-30)
        r = r_l - (2 / c2) * (v2 * r_l).sum(1, keepdims=True) * v2
        n[i] = _unit(r - (r * t[i]).sum(1, keepdims=True) * t[i])
    return n


def sweep(positions: np.ndarray, radii: np.ndarray, chains: Chains, sides: int = 8) -> Tubes:
    """Tubes of ``sides`` sides around every chain of ``chains`` over graph ``positions`` (N, 3)."""
    s = int(sides)
    p = positions[chains.nodes]
    r = radii[chains.radius_node]
    t, bend, miter = _tangents(p, chains)
    nrm = _frames(p, t, chains)
    bin_ = np.cross(t, nrm)
    theta = 2 * np.pi * np.arange(s + 1) / s
    theta[-1] = 0.0  # the seam vertex sits exactly on the first one
    circle = np.cos(theta)[None, :, None] * nrm[:, None] + np.sin(theta)[None, :, None] * bin_[:, None]
    along = (circle * bend[:, None]).sum(-1, keepdims=True) * bend[:, None]  # (M, s+1, 3)
    # a ring in the bisecting plane is stretched by 1/cos(turn/2) across the bend, so the tube keeps
    # its radius through the joint instead of pinching; its normals shrink the other way
    ring = p[:, None] + r[:, None, None] * (circle + (miter[:, None, None] - 1) * along)
    radial = _unit(circle + (1 / miter[:, None, None] - 1) * along)
    m = len(p)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1) if m > 1 else np.zeros(0)
    arc = np.r_[0.0, np.cumsum(seg)]
    arc -= arc[chains.starts[chains.chain]]
    circ = 2 * np.pi * np.maximum(r[chains.starts[chains.chain]], 1e-6)
    u = np.broadcast_to(np.arange(s + 1) / s, (m, s + 1))
    v = np.broadcast_to((arc / circ)[:, None], (m, s + 1))
    faces, face_chain = _side_faces(chains, s)
    cap_f, cap_chain, cap_pos, cap_nrm = _caps(p, t, chains, s, m * (s + 1))
    return Tubes(
        np.concatenate([ring.reshape(-1, 3), cap_pos]),
        np.concatenate([radial.reshape(-1, 3), cap_nrm]),
        np.concatenate([np.stack([u, v], -1).reshape(-1, 2), np.full((len(cap_pos), 2), 0.5)]),
        np.concatenate([faces, cap_f]),
        np.concatenate([face_chain, cap_chain]),
    )


def _side_faces(chains: Chains, s: int) -> tuple[np.ndarray, np.ndarray]:
    """Two outward triangles per ring quad of every segment inside a chain."""
    m = len(chains.nodes)
    seg = np.flatnonzero(chains.chain[:-1] == chains.chain[1:]) if m > 1 else np.zeros(0, np.int64)
    j = np.arange(s)
    a = seg[:, None] * (s + 1) + j
    b, c, d = a + 1, a + s + 2, a + s + 1
    tri = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=2).reshape(-1, 3)
    return tri, np.repeat(chains.chain[seg], 2 * s)


def _caps(p: np.ndarray, t: np.ndarray, chains: Chains, s: int, base: int):
    """Fan caps closing both ends of every chain: faces, their chains, centre positions and normals."""
    first, last = chains.starts[:-1], chains.starts[1:] - 1
    c = len(first)
    j = np.arange(s)
    centre0 = base + np.arange(c)
    centre1 = base + c + np.arange(c)
    r0 = first[:, None] * (s + 1) + j
    r1 = last[:, None] * (s + 1) + j
    f0 = np.stack([np.repeat(centre0, s).reshape(c, s), r0 + 1, r0], -1).reshape(-1, 3)
    f1 = np.stack([np.repeat(centre1, s).reshape(c, s), r1, r1 + 1], -1).reshape(-1, 3)
    chain = np.arange(c)
    return (np.concatenate([f0, f1]), np.r_[np.repeat(chain, s), np.repeat(chain, s)],
            np.concatenate([p[first], p[last]]), np.concatenate([-t[first], t[last]]))
