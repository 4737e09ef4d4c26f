"""Small geometry over numpy arrays: polylines, rigid and similarity transforms, quaternions.

Frames: right-handed, Z up, metres. Quaternions are ``wxyz``. Transforms are 4x4 ``T_to_from``.
"""

from __future__ import annotations

import numpy as np


def polyline_lengths(points: np.ndarray) -> np.ndarray:
    """Cumulative arc length (N,) of a polyline ``points`` (N, 3); starts at 0."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def resample_polyline(points: np.ndarray, n: int) -> np.ndarray:
    """``n`` points (n, 3) equally spaced by arc length along ``points`` (N, 3), ends included."""
    points = np.asarray(points, dtype=np.float64)
    s = polyline_lengths(points)
    if s[-1] <= 0:
        return np.repeat(points[:1], n, axis=0)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, points[:, k]) for k in range(3)], axis=1)


def point_polyline_distance(q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (M,) from each query ``q`` (M, 3) to the polyline ``points`` (N, 3)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 3)
    a, b = points[:-1], points[1:]
    ab = b - a
    denom = np.maximum((ab * ab).sum(axis=1), 1e-300)
    t = np.clip(((q[:, None, :] - a[None]) * ab[None]).sum(axis=2) / denom, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(q[:, None, :] - closest, axis=2).min(axis=1) if len(q) else np.zeros(0)


def quat_to_matrix(wxyz: np.ndarray) -> np.ndarray:
    """3x3 rotation of a unit quaternion ``wxyz`` (4,)."""
    w, x, y, z = np.asarray(wxyz, dtype=np.float64) / np.linalg.norm(wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` radians about ``axis`` (3,) (right-hand rule)."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    h = angle / 2
    return quat_to_matrix(np.concatenate([[np.cos(h)], np.sin(h) * axis]))


def make_transform(R: np.ndarray | None = None, t: np.ndarray | None = None, scale: float = 1.0) -> np.ndarray:
    """4x4 similarity ``[s R | t]``."""
    T = np.eye(4)
    T[:3, :3] = scale * (np.eye(3) if R is None else np.asarray(R, dtype=np.float64))
    if t is not None:
        T[:3, 3] = t
    return T


def apply_transform(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform ``T`` to ``points`` (N, 3)."""
    points = np.asarray(points, dtype=np.float64)
    return points @ T[:3, :3].T + T[:3, 3]


def zup_to_yup(points: np.ndarray) -> np.ndarray:
    """World (Z up) to glTF (Y up): (x, y, z) -> (x, z, -y). Right-handed both sides."""
    p = np.asarray(points)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def yup_to_zup(points: np.ndarray) -> np.ndarray:
    """glTF (Y up) to world (Z up): (x, y, z) -> (x, -z, y). Inverse of ``zup_to_yup``."""
    p = np.asarray(points)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
