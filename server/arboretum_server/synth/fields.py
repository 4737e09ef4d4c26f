"""Guiding-vector rules (Xu and Mould 2015, section 3.2.1): how a node's vector follows its parent's.

A guiding vector is stored as polar angle theta (from +Z, radians) and azimuth phi. Rotating the
parent's vector about ``up x parent`` by alpha keeps the azimuth and adds alpha to theta (a positive
alpha bends away from up, i.e. outwards and down); theta is clamped to [0, pi]. When the parent's vector
is vertical the axis is taken from the traversed edge instead (``up x edge``, section 3.2.1), so a
branch leaving a vertical trunk bends in the direction of its first edge.

Rules (``Rotation.kind``):

* ``piecewise``  Eq. 1: alpha(h) = alpha1 for h <= h0, alpha2 after (h = hops from the source);
* ``random``     alpha1 = R, a random angle in ``random_range`` drawn once per node (Fig. 6c);
* ``global``     Eq. 2: alpha = theta * sqrt(beta / pi), beta the angle between the node's position
  (root at the origin) and up;
* ``helical``, ``rotational``, ``spherical``  directly set fields (Fig. 8): the vector is a function of
  the position only: a helix about the Z axis climbing at ``pitch`` degrees, horizontal circles about
  Z, and the upward meridian direction on spheres about the root.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INCREMENTAL = ("piecewise", "random", "global")
FIELDS = ("helical", "rotational", "spherical")


@dataclass(frozen=True)
class Rotation:
    """How guiding vectors are assigned in one iteration (angles in degrees)."""

    kind: str = "piecewise"
    """One of piecewise, random, global (incremental) or helical, rotational, spherical (fields)."""
    alpha1: float = 0.0
    """alpha_1 of Eq. 1: rotation per hop while h <= h0, degrees."""
    alpha2: float = 0.0
    """alpha_2 of Eq. 1: rotation per hop once h > h0, degrees."""
    h0: int = 0
    """h_0 of Eq. 1: the switch-over hop count."""
    random_range: tuple[float, float] = (30.0, 120.0)
    """R of Fig. 6(c): alpha_1 drawn uniformly in this range per node, degrees."""
    theta: float = 25.0
    """theta of Eq. 2, degrees."""
    pitch: float = 45.0
    """Helical field: climb angle above the horizontal, degrees."""

    def __post_init__(self) -> None:
        if self.kind not in INCREMENTAL + FIELDS:
            raise ValueError(
                f"Rotation.kind must be one of {INCREMENTAL + FIELDS}, got {self.kind!r}"
            )
        object.__setattr__(self, "random_range", tuple(float(x) for x in self.random_range))


def incremental_angles(
    rot: Rotation, points: np.ndarray, root: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, float]:
    """Per-node rotation angles (radians) for h <= h0 and h > h0, and h0 (inf: always the first)."""
    n = len(points)
    if rot.kind == "piecewise":
        return np.full(n, np.radians(rot.alpha1)), np.full(n, np.radians(rot.alpha2)), rot.h0
    if rot.kind == "random":
        lo, hi = np.radians(rot.random_range)
        return rng.uniform(lo, hi, n), np.full(n, np.radians(rot.alpha2)), rot.h0
    rel = points - root
    norm = np.maximum(np.linalg.norm(rel, axis=1), 1e-12)
    beta = np.arccos(np.clip(rel[:, 2] / norm, -1.0, 1.0))
    a = np.radians(rot.theta) * np.sqrt(beta / np.pi)
    return a, a, np.inf


def field_angles(
    rot: Rotation, points: np.ndarray, root: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) (N,) each of a directly set field at ``points`` (N, 3)."""
    rel = points - root
    azim = np.arctan2(rel[:, 1], rel[:, 0])
    rho = np.hypot(rel[:, 0], rel[:, 1])
    tangent = azim + np.pi / 2  # counter-clockwise about +Z
    if rot.kind == "helical":
        theta = np.full(len(points), np.pi / 2 - np.radians(rot.pitch))
        return np.where(rho > 1e-9, theta, 0.0), tangent
    if rot.kind == "rotational":
        return np.where(rho > 1e-9, np.pi / 2, 0.0), tangent
    # spherical: up along the meridian of the sphere about the root, i.e. the polar angle of the
    # position minus 90 degrees, pointing back towards the axis
    polar = np.arctan2(rho, rel[:, 2])
    return np.abs(np.pi / 2 - polar), np.where(polar > np.pi / 2, azim, azim + np.pi)


def vectors(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit vectors (..., 3) of polar angles ``theta`` and azimuths ``phi``."""
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)
