"""A perspective look-at camera in the Z-up world: matrices, orbiting, and framing a bounding box.

Matrices are 4x4 float64 for column vectors (``p_clip = P @ V @ p_world``), OpenGL clip conventions
(camera looks down its -Z axis, depth -1..1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

VIEWS: dict[str, tuple[float, float]] = {
    "front": (-90.0, 0.0),
    "side": (0.0, 0.0),
    "top": (-90.0, 90.0),
    "iso": (-60.0, 25.0),
}
"""View name -> (azimuth, elevation) in degrees of the eye direction seen from the target.
Azimuth is measured from +X towards +Y: 'front' looks from -Y, 'side' from +X, 'top' from +Z."""


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike) -> np.ndarray:
    """View matrix V (4, 4): world -> camera."""
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:  # looking along ``up``: pick another up
        s = np.cross(f, [0.0, 1.0, 0.0] if abs(f[1]) < 0.9 else [1.0, 0.0, 0.0])
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    V = np.eye(4)
    V[0, :3], V[1, :3], V[2, :3] = s, u, -f
    V[:3, 3] = -V[:3, :3] @ eye
    return V


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """Projection matrix P (4, 4) for a vertical field of view in degrees."""
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2)
    P = np.zeros((4, 4))
    P[0, 0], P[1, 1] = f / aspect, f
    P[2, 2], P[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    P[3, 2] = -1.0
    return P


def direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector (3,) from the target towards the eye."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


@dataclass(frozen=True)
class Camera:
    """A perspective camera orbiting ``target`` at ``distance``."""

    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """World point looked at, metres."""
    distance: float = 5.0
    """Eye-target distance, metres."""
    azimuth: float = -60.0
    """Degrees, eye direction from +X towards +Y."""
    elevation: float = 25.0
    """Degrees above the horizontal plane (-90..90)."""
    fov_y: float = 40.0
    """Vertical field of view, degrees."""
    near: float = 0.01
    far: float = 100.0

    @property
    def eye(self) -> np.ndarray:
        return np.asarray(self.target, np.float64) + self.distance * direction(self.azimuth, self.elevation)

    @property
    def up(self) -> np.ndarray:
        """+Z, except when looking straight down or up, where the screen's up is the horizontal
        direction pointing away from the eye's azimuth (so 'top' shows +Y upwards)."""
        if abs(self.elevation) > 89.0:
            return -np.sign(self.elevation) * direction(self.azimuth, 0.0)
        return np.array([0.0, 0.0, 1.0])

    def view_matrix(self) -> np.ndarray:
        return look_at(self.eye, self.target, self.up)

    def projection_matrix(self, aspect: float) -> np.ndarray:
        return perspective(self.fov_y, aspect, self.near, self.far)

    def orbit(self, d_azimuth: float, d_elevation: float) -> Camera:
        """The camera turned about its target by the given degrees (elevation clamped to +-90)."""
        el = float(np.clip(self.elevation + d_elevation, -90.0, 90.0))
        return replace(self, azimuth=(self.azimuth + d_azimuth) % 360.0, elevation=el)

    def project(self, points: ArrayLike, size: tuple[int, int]) -> np.ndarray:
        """Pixel coordinates (N, 2) (x right, y down, origin top-left) of world ``points`` (N, 3)."""
        w, h = size
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        clip = (self.projection_matrix(w / h) @ self.view_matrix() @ np.c_[pts, np.ones(len(pts))].T).T
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.stack([(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h], axis=1)


def fit_camera(bounds: ArrayLike, view: str = "iso", aspect: float = 16 / 9, fov_y: float = 40.0,
               margin: float = 1.08) -> Camera:
    """A camera looking at the centre of ``bounds`` (2, 3) from ``view`` ('front', 'side', 'top',
    'iso') at the smallest distance at which all 8 box corners fall inside the frame (times ``margin``)."""
    if view not in VIEWS:
        raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
    lo, hi = np.asarray(bounds, np.float64)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    az, el = VIEWS[view]
    cam = Camera(target=tuple(centre), distance=1.0, azimuth=az, elevation=el, fov_y=fov_y)
    V = cam.view_matrix()[:3, :3]  # rotation only: corners relative to the target
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    c = (corners - centre) @ V.T  # camera axes: x right, y up, -z forward
    tan_y = math.tan(math.radians(fov_y) / 2)
    tan_x = tan_y * aspect
    # A corner at (x, y, z) relative to the target is in frame when |x| <= (d - z) tan_x, same for y.
    need = np.maximum(np.abs(c[:, 0]) / tan_x, np.abs(c[:, 1]) / tan_y) + c[:, 2]
    dist = max(float(need.max()) * margin, radius * 0.1)
    return replace(cam, distance=dist, near=max(dist - 2 * radius, dist * 1e-3), far=dist + 3 * radius)
