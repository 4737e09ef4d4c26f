"""CPU geometry for the renderer in numpy (no GL): tubes along polylines, vertex normals, primitives.

Tubes use rotation-minimising frames by the double-reflection method (Wang et al. 2008), computed for
many polylines at once: polylines are grouped by similar length and padded, and the only Python loop
runs over vertex positions, not over polylines.
"""

from __future__ import annotations

import numpy as np

EPS = 1e-12


def _normalize(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors of ``v`` (..., 3) and a mask of the ones that were not ~zero."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n[..., 0] > EPS
    return v / np.maximum(n, EPS), ok


def _any_perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector (B, 3) perpendicular to each unit ``t`` (B, 3)."""
    axis = np.zeros_like(t)
    axis[np.arange(len(t)), np.argmin(np.abs(t), axis=1)] = 1.0
    return _normalize(np.cross(t, axis))[0]


def _tangents(P: np.ndarray) -> np.ndarray:
    """Unit tangents (B, L, 3) of padded polylines ``P`` (B, L, 3); zero where undefined."""
    fwd, _ = _normalize(np.diff(P, axis=1))
    t = np.zeros_like(P)
    t[:, :-1] += fwd
    t[:, 1:] += fwd
    t, ok = _normalize(t)
    return t * ok[..., None]


def _frames(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangent, normal, binormal (each (B, L, 3)) along padded polylines by double reflection."""
    T = _tangents(P)
    for k in range(1, P.shape[1]):  # fill undefined tangents (repeated points) from the previous one
        bad = ~(np.abs(T[:, k]).sum(axis=1) > 0)
        T[bad, k] = T[bad, k - 1]
    for k in range(P.shape[1] - 2, -1, -1):
        bad = ~(np.abs(T[:, k]).sum(axis=1) > 0)
        T[bad, k] = T[bad, k + 1]
    bad = ~(np.abs(T).sum(axis=2) > 0)
    T[bad] = (0.0, 0.0, 1.0)
    N = np.zeros_like(P)
    N[:, 0] = _any_perpendicular(T[:, 0])
    for k in range(1, P.shape[1]):
        v1 = P[:, k] - P[:, k - 1]
        c1 = (v1 * v1).sum(axis=1, keepdims=True)
        s1 = np.where(c1 > EPS, 2.0 / np.maximum(c1, EPS), 0.0)
        rL = N[:, k - 1] - s1 * (v1 * N[:, k - 1]).sum(axis=1, keepdims=True) * v1
        tL = T[:, k - 1] - s1 * (v1 * T[:, k - 1]).sum(axis=1, keepdims=True) * v1
        v2 = T[:, k] - tL
        c2 = (v2 * v2).sum(axis=1, keepdims=True)
        s2 = np.where(c2 > EPS, 2.0 / np.maximum(c2, EPS), 0.0)
        n = rL - s2 * (v2 * rL).sum(axis=1, keepdims=True) * v2
        n = n - (n * T[:, k]).sum(axis=1, keepdims=True) * T[:, k]  # keep exactly perpendicular
        n, ok = _normalize(n)
        N[:, k] = np.where(ok[:, None], n, _any_perpendicular(T[:, k]))
    return T, N, np.cross(T, N)


def _tube_group(lines: list[tuple[np.ndarray, np.ndarray]], sides: int):
    """Tube vertices/normals/faces/owner for polylines of similar length (local indices)."""
    lens = np.array([len(p) for p, _ in lines])
    B, L = len(lines), int(lens.max())
    P = np.zeros((B, L, 3))
    R = np.zeros((B, L))
    for b, (p, r) in enumerate(lines):
        P[b, : len(p)], P[b, len(p):] = p, p[-1]
        R[b, : len(p)], R[b, len(p):] = r, r[-1]
    T, N, Bn = _frames(P)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring_n = np.cos(ang)[None, None, :, None] * N[:, :, None] + np.sin(ang)[None, None, :, None] * Bn[:, :, None]
    ring_p = P[:, :, None] + R[:, :, None, None] * ring_n  # (B, L, S, 3)
    valid = np.arange(L)[None, :] < lens[:, None]  # (B, L)
    idx = np.full((B, L, sides), -1, np.int64)
    idx[valid] = np.arange(int(valid.sum()) * sides).reshape(-1, sides)
    verts, norms = ring_p[valid].reshape(-1, 3), ring_n[valid].reshape(-1, 3)
    owner = np.repeat(np.arange(B), lens * sides)
    seg = np.arange(L - 1)[None, :] < (lens - 1)[:, None]  # (B, L-1)
    a = idx[:, :-1][seg]
    d = idx[:, 1:][seg]
    b_, c_ = np.roll(a, -1, axis=1), np.roll(d, -1, axis=1)
    faces = np.concatenate([np.stack([a, b_, c_], -1), np.stack([a, c_, d], -1)], axis=1).reshape(-1, 3)
    # End caps: a centre vertex per end and a fan over its ring.
    first, last = idx[:, 0], idx[np.arange(B), lens - 1]
    base = len(verts)
    centres = np.concatenate([P[:, 0], P[np.arange(B), lens - 1]])
    cap_n = np.concatenate([-T[:, 0], T[np.arange(B), lens - 1]])
    ci = base + np.arange(2 * B)[:, None]
    ring = np.concatenate([first, last])
    nxt = np.roll(ring, -1, axis=1)
    fan_start = np.stack([np.broadcast_to(ci, ring.shape), nxt, ring], -1)[:B]
    fan_end = np.stack([np.broadcast_to(ci, ring.shape), ring, nxt], -1)[B:]
    faces = np.concatenate([faces, fan_start.reshape(-1, 3), fan_end.reshape(-1, 3)])
    verts = np.concatenate([verts, centres])
    norms = np.concatenate([norms, cap_n])
    owner = np.concatenate([owner, np.arange(B), np.arange(B)])
    return verts, norms, faces, owner


def tube_mesh(lines: list[tuple[np.ndarray, np.ndarray]], sides: int = 8):
    """Closed tubes around polylines.

    Args:
        lines: for each polyline, ``(points (N, 3), radii (N,))`` with N >= 2.
        sides: ring vertex count.

    Returns:
        vertices (V, 3) float64, normals (V, 3) float64 (unit, outward), faces (F, 3) int64
        (counter-clockwise seen from outside), owner (V,) int64 (index of the polyline of each vertex).
    """
    if not lines:
        z3 = np.zeros((0, 3))
        return z3, z3, np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    lines = [(np.asarray(p, np.float64), np.asarray(r, np.float64)) for p, r in lines]
    bucket = np.ceil(np.log2([len(p) for p, _ in lines])).astype(int)
    out_v, out_n, out_f, out_o, offset = [], [], [], [], 0
    for key in np.unique(bucket):
        members = np.flatnonzero(bucket == key)
        v, n, f, o = _tube_group([lines[i] for i in members], sides)
        out_v.append(v)
        out_n.append(n)
        out_f.append(f + offset)
        out_o.append(members[o])
        offset += len(v)
    return np.concatenate(out_v), np.concatenate(out_n), np.concatenate(out_f), np.concatenate(out_o)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3) of a mesh; (0, 0, 1) for unused vertices."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    acc = np.zeros_like(v)
    for k in range(3):
        np.add.at(acc, f[:, k], fn)
    n, ok = _normalize(acc)
    n[~ok] = (0.0, 0.0, 1.0)
    return n


def cylinder(sides: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A closed unit cylinder along +Z from z=0 to z=1, radius 1: vertices (V, 3), faces (F, 3)."""
    v, _, f, _ = tube_mesh([(np.array([[0, 0, 0], [0, 0, 1.0]]), np.ones(2))], sides)
    return v, f


def quad() -> tuple[np.ndarray, np.ndarray]:
    """A unit square in the XZ plane (x in -0.5..0.5, z in 0..1), two triangles (a leaf card)."""
    v = np.array([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 1], [-0.5, 0, 1]], np.float64)
    return v, np.array([[0, 1, 2], [0, 2, 3]], np.int64)


def uv_sphere(rings: int = 12, segments: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A closed unit sphere: vertices (V, 3), outward counter-clockwise faces (F, 3)."""
    th = np.linspace(0, np.pi, rings + 1)[1:-1]
    ph = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack(np.broadcast_arrays(np.sin(th)[:, None] * np.cos(ph), np.sin(th)[:, None] * np.sin(ph),
                                        np.cos(th)[:, None]), -1).reshape(-1, 3)
    v = np.concatenate([[[0, 0, 1.0]], ring, [[0, 0, -1.0]]])
    idx = 1 + np.arange((rings - 1) * segments).reshape(rings - 1, segments)
    nxt = np.roll(idx, -1, axis=1)
    top = np.stack([np.zeros(segments, int), idx[0], nxt[0]], -1)
    bot = np.stack([np.full(segments, len(v) - 1), nxt[-1], idx[-1]], -1)
    a, b, c, d = idx[:-1], nxt[:-1], nxt[1:], idx[1:]
    body = np.concatenate([np.stack([a, d, c], -1), np.stack([a, c, b], -1)]).reshape(-1, 3)
    return v, np.concatenate([top, body, bot])
