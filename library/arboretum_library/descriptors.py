"""Descriptors and keyword tags of an example (VRTree section 3.4, "Examples library", Fig. 6).

The paper classifies examples by the curvature of the main branch and the number of lobes, and lets users
search by "dense", "sparse", "straight" and "curved". We fix the meaning of each here, once, so every
library agrees:

- curvature: how far the main branch bows from the chord between its ends, as the angle (radians) of
  the circular arc that bows as far (``polyline_curvature``): a straight branch scores 0, a quarter
  circle pi/2. Smoothing first makes it insensitive to the zig-zag of graph shortest paths, and it is
  independent of scale.
- dense / sparse: lobe count at or above ``dense_lobes`` / at or below ``sparse_lobes``.
- straight / curved: within a library, relative to the examples of the same species once there are
  ``RELATIVE_MIN`` of them: at or below the lower tercile of their curvatures / at or above the upper
  one (``relative_curvature_tags``), so the keywords split any library into its straighter and curvier
  thirds. Below that, and as stored with each example, the fixed ``TagThresholds``: curvature below
  ``straight_rad`` / above ``curved_rad``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import point_polyline_distance, resample_polyline
from .model import HBL, Descriptors

CURVATURE_SEGMENTS = 8
RELATIVE_MIN = 6
"""Examples of one species a library needs before 'straight' and 'curved' become relative to them."""
CURVATURE_TAGS = ("straight", "curved")


@dataclass(frozen=True)
class TagThresholds:
    """Where the keyword tags start."""

    dense_lobes: int = 6
    """Lobe count at or above which an example is 'dense'."""
    sparse_lobes: int = 3
    """Lobe count at or below which an example is 'sparse'."""
    straight_rad: float = 0.35
    """Curvature (radians) below which the main branch is 'straight' (about 20 degrees in all)."""
    curved_rad: float = 0.7
    """Curvature (radians) above which the main branch is 'curved' (about 40 degrees in all)."""


def polyline_curvature(points: np.ndarray, segments: int = CURVATURE_SEGMENTS) -> float:
    """How much a polyline ``points`` (N, 3) bends, in radians: the angle of the circular arc that bows
    as far from its chord, 4 atan(2 s / c) for the largest distance s of the polyline from the chord c
    between its ends (straight 0, a quarter circle pi/2, a half circle pi).

    The polyline is first resampled densely and smoothed with a moving average 1/``segments`` of its
    length long (odd reflection at the ends keeps straight lines straight). Unlike the total turning
    angle, the bow does not add up the small wiggles that graph shortest paths keep after smoothing,
    which made every main branch of a scanned tree read as 'curved' (1.0-1.6 rad for branches whose
    chord is 93-98 % of their length).
    """
    dense_per_segment = 16
    dense = resample_polyline(points, segments * dense_per_segment + 1)
    h = dense_per_segment // 2
    padded = np.concatenate([2 * dense[0] - dense[h:0:-1], dense, 2 * dense[-1] - dense[-2 : -h - 2 : -1]])
    kernel = np.ones(2 * h + 1) / (2 * h + 1)
    smooth = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(3)], axis=1)
    chord = smooth[-1] - smooth[0]
    c = float(np.linalg.norm(chord))
    if c <= 1e-12:
        return 0.0 if np.ptp(smooth, axis=0).max() <= 1e-12 else 2 * np.pi
    rel = smooth - smooth[0]
    along = rel @ (chord / c)
    s = float(np.linalg.norm(rel - along[:, None] * (chord / c), axis=1).max())
    return float(4.0 * np.arctan(2.0 * s / c))


def describe(structure: HBL) -> Descriptors:
    """Descriptors of an example's structure (main branch = ``structure.branches[0]``)."""
    main = structure.branches[0]
    centres = np.array([lb.centre for lb in structure.lobes]).reshape(-1, 3)
    spread = float(point_polyline_distance(centres, main.points).mean()) if len(centres) else 0.0
    return Descriptors(
        curvature=polyline_curvature(main.points),
        lobe_count=len(structure.lobes),
        length=main.length,
        spread=spread,
        height=structure.height,
    )


def tags_for(d: Descriptors, t: TagThresholds = TagThresholds()) -> tuple[str, ...]:
    """The keyword tags that ``d`` earns under thresholds ``t``."""
    tags = []
    if d.lobe_count >= t.dense_lobes:
        tags.append("dense")
    if d.lobe_count <= t.sparse_lobes:
        tags.append("sparse")
    if d.curvature < t.straight_rad:
        tags.append("straight")
    if d.curvature > t.curved_rad:
        tags.append("curved")
    return tuple(tags)


def tercile_bounds(curvature: np.ndarray, minimum: int = RELATIVE_MIN) -> tuple[float, float] | None:
    """(lower, upper) terciles of ``curvature`` (N,), or None with fewer than ``minimum`` values."""
    c = np.asarray(curvature, dtype=np.float64)
    if len(c) < minimum:
        return None
    return float(np.quantile(c, 1 / 3)), float(np.quantile(c, 2 / 3))


def relative_curvature_tags(tags: tuple[str, ...], curvature: float, bounds: tuple[float, float] | None,
                            t: TagThresholds = TagThresholds()) -> tuple[str, ...]:
    """``tags`` with 'straight'/'curved' decided by the species' tercile ``bounds`` (None: by ``t``)."""
    lo, hi = bounds if bounds is not None else (np.nextafter(t.straight_rad, -np.inf), np.nextafter(t.curved_rad, np.inf))
    new = "straight" if curvature <= lo else "curved" if curvature >= hi else None
    at = next((i for i, x in enumerate(tags) if x in CURVATURE_TAGS), len(tags))  # keep the tag's place
    out = [x for x in tags if x not in CURVATURE_TAGS]
    if new is not None:
        out.insert(min(at, len(out)), new)
    return tuple(out)
