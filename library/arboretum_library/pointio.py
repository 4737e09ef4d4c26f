"""Point clouds in and out: ``read_points`` for the usual scan formats, ``write_points``, ``scan_stats``.

Read: .xyz .txt .csv .asc .pts (text), .ply, .pcd (v0.7 ascii/binary/binary_compressed), .las .laz,
.npy. Write: .ply .xyz .txt .npy. Every cloud comes back Z up in metres (Y-up and upside-down files
are turned with ``pointio_up.turn_to_zup``), optionally recentred on its
trunk base, scaled to a height and thinned evenly to a number of points (VRTree section 4: 12,000 points,
0.8 m). Every problem with a file raises one ``InputError`` naming it. The per-format code lives in
``pointio_formats`` (text tables in ``pointio_text``, PCD in ``pointio_pcd``); the way up in
``pointio_up``; the spatial helpers (trunk base, even thinning, spacing) in ``pointio_spatial``;
``scan_stats`` and ``precision_note`` in ``pointio_stats``.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from . import pointio_formats as fmt
from .errors import InputError, ValidationError
from .model import LEAF, frozen_array
from .pointio_pcd import read_pcd
from .pointio_spatial import column_bounds, even_sample_indices, median_spacing, trunk_base
from .pointio_stats import precision_note, scan_stats
from .pointio_text import read_text
from .pointio_up import (
    AUTO_Y_CONFIDENCE,
    UP_DIRECTIONS,
    UpGuess,
    auto_up,
    guess_up,
    guess_up_axis,
    turn_to_zup,
)

__all__ = [
    "AUTO_Y_CONFIDENCE",
    "auto_up",
    "PointCloud",
    "ReadOptions",
    "VRTREE_PREPROCESS",
    "READERS",
    "WRITERS",
    "read_points",
    "write_points",
    "scan_stats",
    "guess_up_axis",
    "guess_up",
    "trunk_base",
    "even_sample_indices",
    "median_spacing",
    "precision_note",
]

READERS: dict[str, Callable[[Path], fmt.Raw]] = {
    ".xyz": read_text,
    ".txt": read_text,
    ".csv": read_text,
    ".asc": read_text,
    ".pts": read_text,
    ".ply": fmt.read_ply,
    ".pcd": read_pcd,
    ".las": fmt.read_las,
    ".laz": fmt.read_las,
    ".npy": fmt.read_npy,
}
"""Readers by lower-case file extension."""
WRITERS: dict[str, Callable[[BinaryIO, np.ndarray], None]] = {
    ".ply": fmt.write_ply,
    ".xyz": fmt.write_text,
    ".txt": fmt.write_text,
    ".npy": fmt.write_npy,
}
"""Writers by lower-case file extension."""


@dataclass(frozen=True, eq=False)
class PointCloud:
    """A scanned tree as points with optional per-point attributes. Arrays are read-only copies."""

    points: NDArray[np.float64]
    """(N, 3) float64, metres, right-handed, Z up."""
    colors: NDArray[np.float32] | None = None
    """(N, 3) float32 RGB in [0, 1], or None."""
    labels: NDArray[np.uint8] | None = None
    """(N,) uint8: ``model.WOOD`` (0) or ``model.LEAF`` (1), or None."""
    branch_ids: NDArray[np.int32] | None = None
    """(N,) int32: the branch each point was sampled from (-1 for none), or None."""
    source: str = ""
    """Path of the file it was read from ('' when built in memory)."""
    up_axis: str = "z"
    """The way up of the file as read (``UP_DIRECTIONS``): 'z', 'y', or 'z-down' / 'y-down' for a file
    standing upside down (points are Z up, the right way up, whichever)."""
    resolution: float = 0.0
    """Metres: the largest gap between coordinate values the file's type could hold over the cloud's
    extent (float32: the spacing at the largest magnitude, 0.5 m at 5.4e6 m; LAS: the largest scale
    factor; integers: 1 unit), scaled with the cloud; 0.0 for float64, text and clouds built in memory.
    See ``precision_note``."""
    stored_as: str = ""
    """How the file stored the coordinates: 'float32', 'float64', 'text', 'LAS integers scaled by
    0.001'..., or '' when built in memory."""
    up_guess: UpGuess | None = None
    """``guess_up`` of the points in the file's own frame, when ``read_points`` made it (``up='auto'``
    on any format but LAS/LAZ), else None."""

    def __post_init__(self) -> None:
        pts = frozen_array(self, "points", self.points, np.float64, (None, 3))
        n = len(pts)
        if self.colors is not None:
            col = frozen_array(self, "colors", self.colors, np.float32, (n, 3))
            if col.size and (col.min() < 0 or col.max() > 1):
                raise ValidationError("PointCloud.colors: values must lie in [0, 1]")
        if self.labels is not None:
            lab = frozen_array(self, "labels", self.labels, np.uint8, (n,))
            if lab.size and lab.max() > LEAF:
                raise ValidationError("PointCloud.labels: values must be 0 (wood) or 1 (leaf)")
        if self.branch_ids is not None:
            frozen_array(self, "branch_ids", self.branch_ids, np.int32, (n,))
        if self.up_axis not in UP_DIRECTIONS:
            ways = ", ".join(UP_DIRECTIONS)
            raise ValidationError(f"PointCloud.up_axis: must be one of {ways}, got {self.up_axis!r}")
        if not (np.isfinite(self.resolution) and self.resolution >= 0):
            raise ValidationError(f"PointCloud.resolution: must be a number >= 0, got {self.resolution}")

    def __len__(self) -> int:
        return len(self.points)


UP_CHOICES = ("auto", "z", "y")
"""The up axes a mesh file may be read with (``export.mesh_up``: ``render --up``, ``modules --up``)."""
SCAN_UP_CHOICES = ("auto", *UP_DIRECTIONS)
"""The ways up a point cloud file may be read with (``ReadOptions.up``, ``scan --up``): 'z-down' and
'y-down' for a file standing upside down. Not '-z': argparse takes ``--up -z`` for an option."""


@dataclass(frozen=True)
class ReadOptions:
    """How ``read_points`` prepares a cloud. The defaults change nothing but the up axis."""

    up: str = "auto"
    """The way up of the file (``SCAN_UP_CHOICES``): 'auto' (``guess_up``, see ``auto_up``), 'z', 'y',
    'z-down' or 'y-down' (turned with ``turn_to_zup``)."""
    recentre: bool = False
    """Translate so the trunk base (``trunk_base``) is the origin."""
    target_height: float | None = None
    """Scale uniformly about the trunk base so the height (Z extent) is this, metres. VRTree: 0.8."""
    max_points: int | None = None
    """Thin evenly to at most this many points (``even_sample_indices``). VRTree: 12,000."""
    seed: int = 0
    """Seed of the random choices in thinning."""

    def __post_init__(self) -> None:
        if self.up not in SCAN_UP_CHOICES:
            raise InputError(f"up axis must be one of {', '.join(SCAN_UP_CHOICES)}, got {self.up!r}")
        th = self.target_height
        if th is not None and not (np.isfinite(th) and th > 0):
            raise InputError(f"target height must be a number > 0, got {th}")
        if self.max_points is not None and self.max_points < 2:
            raise InputError(f"max points must be at least 2, got {self.max_points}")


MAX_COORDINATE = 1e12
"""Largest coordinate magnitude ``read_points`` and ``arboretum decompose`` (for arrays given it
directly) accept, in any unit: geocentric coordinates in millimetres stay under 1e10, while near 1e154
squared distances, and near 1e308 extents, overflow float64."""

Z_UP_SUFFIXES = (".las", ".laz")
"""Formats whose Z is up by definition (ASPRS LAS: Z is elevation): ``up='auto'`` reads them Z up without
a guess. A wall, a fence or returns under the ground could turn a guess; they cannot turn a LAS file."""


def z_up_by_format(path: str | Path, up_asked: str) -> bool:
    """Whether ``--up up_asked`` reads the file at ``path`` Z up by its format, without a guess: 'auto' on
    a LAS or LAZ file (``Z_UP_SUFFIXES``)."""
    return up_asked == "auto" and str(path).lower().endswith(Z_UP_SUFFIXES)


VRTREE_PREPROCESS = ReadOptions(recentre=True, target_height=0.8, max_points=12_000)
"""The preprocessing of VRTree section 4.1 (Data preprocessing): 12,000 points scaled to 0.8 m."""


def read_points(path: str | Path, options: ReadOptions = ReadOptions()) -> PointCloud:
    """Read a point cloud file into a Z-up ``PointCloud``, prepared as ``options`` asks.

    Steps: read, check (points finite and within ``MAX_COORDINATE``, at least two, not all
    identical), up axis, thin
    (``max_points``), recentre, scale. Colours, labels and branch ids follow the kept points.
    Raises ``InputError`` naming ``path`` for anything wrong with the file.
    """
    path = Path(path)
    raw = _read_raw(path)
    points = _checked_points(path, raw)
    up, guess = options.up, None
    if z_up_by_format(path, up):
        up = "z"
    elif up == "auto":
        guess = guess_up(points)
        up = auto_up(guess)
    points = turn_to_zup(points, up)
    keep = None
    if options.max_points is not None and len(points) > options.max_points:
        keep = even_sample_indices(points, options.max_points, np.random.default_rng(options.seed))
        points = points[keep]
    points, scale = _place(path, points, options)
    try:
        return PointCloud(
            points=points,
            colors=_subset(raw.get("colors"), keep),
            labels=_subset(raw.get("labels"), keep),
            branch_ids=_subset(raw.get("branch_ids"), keep),
            source=str(path),
            up_axis=up,
            resolution=float(raw.get("resolution", 0.0)) * scale,
            stored_as=str(raw.get("stored_as", "")),
            up_guess=guess,
        )
    except ValidationError as exc:
        raise InputError(f"'{path}': {exc}") from None


def _read_raw(path: Path) -> fmt.Raw:
    if not path.exists():
        raise InputError(f"'{path}': no such file")
    if path.is_dir():
        raise InputError(f"'{path}': is a folder, not a point cloud file")
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        known = " ".join(sorted(READERS))
        raise InputError(
            f"'{path}': unknown point cloud format '{path.suffix}' (supported: {known})"
        )
    if path.stat().st_size == 0:
        raise InputError(f"'{path}': is empty: no points")
    try:
        return reader(path)
    except MemoryError:
        raise InputError(f"'{path}': too large to read into memory") from None
    except OSError as exc:
        raise InputError(f"'{path}': cannot be read ({exc.strerror or exc})") from None


def _checked_points(path: Path, raw: fmt.Raw) -> np.ndarray:
    """The (N, 3) float64 points, or InputError: no points, one point, NaN/inf rows, all identical."""
    points = np.asarray(raw["points"], dtype=np.float64)
    if len(points) == 0:
        raise InputError(f"'{path}': holds no points")
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise InputError(
            f"'{path}': {int(bad.sum())} point(s) have NaN or infinite coordinates"
            f" (first at index {int(np.argmax(bad))})"
        )
    big = float(np.abs(column_bounds(points)).max())
    if big > MAX_COORDINATE:
        raise InputError(
            f"'{path}': coordinates up to {big:.3g}, beyond {MAX_COORDINATE:.0e} in any unit;"
            " a file read in the wrong format or units?"
        )
    if len(points) == 1:
        raise InputError(f"'{path}': holds exactly one point; a tree needs many")
    if (points == points[0]).all():
        raise InputError(f"'{path}': all {len(points)} points are identical")
    return points


def _place(path: Path, points: np.ndarray, options: ReadOptions) -> tuple[np.ndarray, float]:
    """Recentre on the trunk base and scale to the target height, as ``options`` asks; and the scale."""
    if not options.recentre and options.target_height is None:
        return points, 1.0
    base = trunk_base(points)
    if options.recentre:
        points = points - base
        base = np.zeros(3)
    scale = 1.0
    if options.target_height is not None:
        height = float(np.ptp(points[:, 2]))
        if height <= 0:
            raise InputError(f"'{path}': cannot scale to a height: all points lie at one height")
        scale = options.target_height / height
        points = base + (points - base) * scale
    return points, scale


def _subset(values: Any, keep: np.ndarray | None) -> np.ndarray | None:
    if values is None:
        return None
    return np.asarray(values) if keep is None else np.asarray(values)[keep]


def write_points(
    path: str | Path,
    points: np.ndarray | PointCloud,
    *,
    colors: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    branch_ids: np.ndarray | None = None,
) -> Path:
    """Write points (N, 3) (or a ``PointCloud``) with optional attributes to .ply, .xyz/.txt or .npy.

    The file appears whole or not at all (a temporary file in the same folder, then ``os.replace``).
    PLY is binary little-endian with x, y, z (double), red, green, blue (uchar), label (uchar) and
    branch_id (int) when present. Returns the path written.
    """
    path = Path(path)
    if isinstance(points, PointCloud):
        cloud = points
        colors = cloud.colors if colors is None else colors
        labels = cloud.labels if labels is None else labels
        branch_ids = cloud.branch_ids if branch_ids is None else branch_ids
        points = cloud.points
    cloud = PointCloud(points=points, colors=colors, labels=labels, branch_ids=branch_ids)
    writer = WRITERS.get(path.suffix.lower())
    if writer is None:
        known = " ".join(sorted(WRITERS))
        raise InputError(f"'{path}': cannot write format '{path.suffix}' (writable: {known})")
    if not path.parent.is_dir():
        raise InputError(f"'{path}': folder '{path.parent}' does not exist")
    table = fmt.vertex_array(cloud.points, cloud.colors, cloud.labels, cloud.branch_ids)
    _atomic_write(path, lambda f: writer(f, table))
    return path


def _atomic_write(path: Path, write: Callable[[BinaryIO], None]) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
