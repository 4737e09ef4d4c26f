"""What ``pointio`` says about a cloud as read: ``scan_stats`` (``arboretum scan info``) and
``precision_note`` (coordinates stored too coarsely for the scan: float32 at UTM, a coarse LAS scale).
Re-exported by ``pointio``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .model import LEAF
from .pointio_spatial import column_bounds, median_spacing
from .pointio_up import auto_up, guess_up, turn_from_zup
from .repeats import distinct_rows

if TYPE_CHECKING:
    from .pointio import PointCloud


PRECISION_FRACTION = 0.1
"""``precision_note`` speaks when the resolution is coarser than this fraction of the point spacing."""


def precision_note(cloud: PointCloud, spacing: float | None = None, points: int | None = None) -> str | None:
    """One line when the file's coordinate type is too coarse for the scan (``cloud.resolution`` above
    ``PRECISION_FRACTION`` of the median point spacing), else None. Such a cloud is read, not refused:
    its points sit on the type's grid. A float32 PLY of a 1 cm tree at UTM coordinates (5.4e6 m: 0.5 m
    grid) decomposed into garbage with no word of why.

    The spacing is ``spacing`` when given, else that of the cloud as it will be used
    (``_used_spacing``): ``points`` is the decomposition's point budget (None or 0: all points), so a
    1 mm LAS grid under a 2.2 mm TLS spacing, harmless at 12,000 points, says nothing. A spacing of 0
    (a single distinct point) says nothing either. Floats name the magnitude of the cloud as held (the
    file's, unless read with ``recentre``): their grid grows with it; LAS and integer grids do not."""
    if cloud.resolution <= 0:
        return None
    budget = ""
    if spacing is None:
        spacing, used = _used_spacing(cloud.points, points)
        budget = f" at {used:,} points" if points else ""
    if spacing <= 0 or cloud.resolution <= PRECISION_FRACTION * spacing:
        return None
    stored = cloud.stored_as or "a coarse type"
    if stored.startswith(("LAS", "int", "uint")):
        where = ""
    else:
        magnitude = float(np.abs(column_bounds(cloud.points)).max()) if len(cloud) else 0.0
        where = f" at magnitudes up to {magnitude:.3g} m"
    return (f"'{cloud.source or 'cloud'}': coordinates stored as {stored}{where} are only "
            f"{_length(cloud.resolution)} apart, coarser than a tenth of the median point spacing "
            f"({_length(spacing)}{budget}): the points sit on that grid; {_precision_fix(stored)}")


def _used_spacing(points: np.ndarray, budget: int | None, seed: int = 0) -> tuple[float, int]:
    """Median nearest-neighbour spacing (metres) of the distinct rows of ``points`` (N, 3), on a random
    sample (seeded) of ``budget`` of them when there are more (None or 0: all), and the number of
    points it was measured on: the spacing the decomposition works at. Repeats are merged first, as
    the decomposition merges them: with every point given twice the spacing of all rows is 0."""
    pts = np.asarray(points, dtype=np.float64)
    pts = pts[distinct_rows(pts)[0]]
    rng = np.random.default_rng(seed)
    if budget and len(pts) > budget:
        pts = pts[np.sort(rng.choice(len(pts), budget, replace=False))]
    return median_spacing(pts, rng), len(pts)


def _precision_fix(stored: str) -> str:
    """What to do about coordinates stored as ``stored``: shifting helps floats only."""
    if stored.startswith("LAS"):
        return "re-export it with a finer scale factor, or as float64 PLY"
    if stored.startswith(("int", "uint")):
        return "re-export it as float64"
    return "re-export it as float64, or shifted near the origin"


def _length(metres: float) -> str:
    return f"{metres:.3g} m" if metres >= 0.1 else f"{metres * 1000:.3g} mm"


def scan_stats(cloud: PointCloud, seed: int = 0) -> dict[str, Any]:
    """Summary of a cloud (JSON-ready): counts, extent, height, up axis and its guess, point spacing.

    ``up_axis`` is the way up the file was read with ('z-down' / 'y-down': it stood upside down and was
    turned); ``up_guess`` and ``up_confidence`` are ``guess_up`` on the points in the file's own frame,
    ``up_by_shape`` the way ``--up auto`` reads a file with that guess (``pointio.auto_up``; LAS and LAZ are
    read Z up whatever it says).
    ``spacing`` is the median nearest-neighbour distance over up to 2,000 sampled points (metres).
    """
    pts = cloud.points
    lo, hi = column_bounds(pts)
    guess = cloud.up_guess or guess_up(turn_from_zup(pts, cloud.up_axis))
    stats: dict[str, Any] = {
        "file": cloud.source,
        "points": len(pts),
        "min": lo.tolist(),
        "max": hi.tolist(),
        "size": (hi - lo).tolist(),
        "height": float(hi[2] - lo[2]),
        "up_axis": cloud.up_axis,
        "up_guess": guess.direction,
        "up_confidence": round(guess.confidence, 3),
        "up_by_shape": auto_up(guess),
        "spacing": median_spacing(pts, np.random.default_rng(seed)),
        "has_colors": cloud.colors is not None,
        "has_labels": cloud.labels is not None,
        "has_branch_ids": cloud.branch_ids is not None,
    }
    if cloud.labels is not None:
        stats["leaf_fraction"] = float(np.mean(cloud.labels == LEAF))
    if cloud.branch_ids is not None:
        stats["branches"] = int(np.unique(cloud.branch_ids[cloud.branch_ids >= 0]).size)
    return stats
