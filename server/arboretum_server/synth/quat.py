"""Vectorised unit-quaternion helpers for the harmonic growth model (``wxyz``, float64).

Every function works on stacks: quaternions ``(..., 4)``, vectors ``(..., 3)``, angles ``(...)`` in
radians. A quaternion ``q`` maps a bud's local frame to the world; ``mul(q, r)`` applies ``r`` in the
local frame of ``q`` (the paper's ``B R W H`` order, equation 1).
"""

from __future__ import annotations

import numpy as np

EX = np.array([1.0, 0.0, 0.0])
EY = np.array([0.0, 1.0, 0.0])
EZ = np.array([0.0, 0.0, 1.0])


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a b`` of quaternions (..., 4) (broadcasting)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) rotating by ``angle`` (...) radians about unit ``axis`` (..., 3) or (3,)."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    s = np.sin(half)[..., None]
    return np.concatenate([np.cos(half)[..., None], s * axis], axis=-1)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) or (3,) by unit quaternions ``q`` (..., 4)."""
    w = q[..., :1]
    u = q[..., 1:]
    v = np.broadcast_to(v, u.shape)
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) with a non-negative ``w`` (one sign per rotation)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def level_frame(direction: np.ndarray, fallback_azimuth: np.ndarray) -> np.ndarray:
    """Bud frames (..., 4) whose local +Z is ``direction`` (..., 3) and local +X is horizontal.

    Local +X is ``direction x up`` (normalised), so a positive rotation about local +X tips the bud
    towards world +Z: the paper's "positive span angle bends upward". For a vertical direction the
    frame is turned by ``fallback_azimuth`` (...) radians about Z instead. Built as
    ``Rz(azimuth) Ry(polar) Rz(-90 deg)``.
    """
    d = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    polar = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    horiz = np.hypot(d[..., 0], d[..., 1])
    azimuth = np.where(horiz > 1e-9, np.arctan2(d[..., 1], d[..., 0]), fallback_azimuth)
    q = mul(axis_angle(EZ, azimuth), axis_angle(EY, polar))
    return normalize(mul(q, axis_angle(EZ, np.full(polar.shape, -0.5 * np.pi))))


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) of one proper rotation matrix ``m`` (3, 3) (Shepperd's method)."""
    tr = np.trace(m)
    cand = np.array([tr, m[0, 0], m[1, 1], m[2, 2]])
    k = int(np.argmax(cand))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i, j, n = [(0, 1, 2), (1, 2, 0), (2, 0, 1)][k - 1]
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[n, n])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (m[n, j] - m[j, n]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + n] = (m[n, i] + m[i, n]) / s
    return normalize(np.array(q))


def from_euler_xyz(angles: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) of intrinsic X-then-Y-then-Z rotations by ``angles`` (..., 3) radians."""
    qx = axis_angle(EX, angles[..., 0])
    qy = axis_angle(EY, angles[..., 1])
    qz = axis_angle(EZ, angles[..., 2])
    return mul(mul(qx, qy), qz)
