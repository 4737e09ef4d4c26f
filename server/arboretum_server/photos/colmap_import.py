"""A COLMAP reconstruction (text or binary model folder) as plain arrays: ``read_model``, ``from_reconstruction``.

A model folder holds ``cameras``, ``images`` and ``points3D`` (``.txt`` or ``.bin``), as written by
COLMAP's mapper or ``Reconstruction.write``. A folder holding numbered sub-folders (COLMAP's
``sparse/0``, ``sparse/1``, ...) is accepted too: the model with the most registered images is read.
COLMAP's world frame is arbitrary (often Y down): ``isolate`` turns the cloud Z up afterwards.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from arboretum_library.errors import InputError

MODEL_FILES = ("cameras", "images", "points3D")


@dataclass(frozen=True, eq=False)
class SfmCloud:
    """Points and cameras of one reconstruction, in the reconstruction's own frame and units."""

    points: np.ndarray
    """(N, 3) float64: 3D points (sparse SfM points, or fused dense points)."""
    colors: np.ndarray
    """(N, 3) float32 RGB in [0, 1]."""
    camera_centres: np.ndarray
    """(V, 3) float64: projection centres of the registered images."""
    camera_up: np.ndarray
    """(V, 3) float64 unit: each registered image's 'up' (its -Y axis) as a world direction."""
    image_names: tuple[str, ...]
    """(V,) names of the registered images, in the order of ``camera_centres``."""
    errors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(N,) float64: mean reprojection error of each point, pixels (empty for dense points)."""
    dense: bool = False
    """True when ``points`` come from dense stereo fusion."""
    stats: dict[str, Any] = field(default_factory=dict)
    """Counts and figures: images, registered, points, mean_reprojection_error_px, focal_px, ..."""


def from_reconstruction(rec: Any, images_total: int | None = None) -> SfmCloud:
    """Arrays of a ``pycolmap.Reconstruction`` (points, colours, registered cameras, statistics)."""
    pts3d = rec.points3D
    ids = sorted(pts3d.keys())
    xyz = np.array([pts3d[i].xyz for i in ids], np.float64).reshape(-1, 3)
    rgb = np.array([pts3d[i].color for i in ids], np.float32).reshape(-1, 3) / 255.0
    err = np.array([pts3d[i].error for i in ids], np.float64)
    img_ids = sorted(rec.reg_image_ids())
    images = [rec.image(i) for i in img_ids]
    centres = np.array([im.projection_center() for im in images], np.float64).reshape(-1, 3)
    up = np.array([_image_up(im) for im in images], np.float64).reshape(-1, 3)
    cams = rec.cameras
    focal = [float(np.mean(c.focal_length_x + c.focal_length_y) / 2) for c in cams.values()]
    stats = {
        "images": int(images_total if images_total is not None else rec.num_images()),
        "registered": len(images),
        "points": len(xyz),
        "cameras": len(cams),
        "focal_px": focal[0] if len(focal) == 1 else focal,
        "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()) if len(xyz) else 0.0,
        "mean_track_length": float(rec.compute_mean_track_length()) if len(xyz) else 0.0,
    }
    return SfmCloud(xyz, rgb, centres, up, tuple(im.name for im in images), err, False, stats)


def _image_up(image: Any) -> np.ndarray:
    """World direction of an image's up (camera -Y; COLMAP cameras look along +Z with Y down)."""
    pose = image.cam_from_world()
    pose = pose() if callable(pose) else pose
    R = np.asarray(pose.rotation.matrix(), np.float64)
    return R.T @ np.array([0.0, -1.0, 0.0])


def is_model_dir(folder: Path) -> bool:
    """True when ``folder`` holds the three model files in text or binary form."""
    return all((folder / f"{n}.bin").is_file() for n in MODEL_FILES) or all(
        (folder / f"{n}.txt").is_file() for n in MODEL_FILES
    )


def model_dirs(folder: Path) -> list[Path]:
    """``folder`` itself if it is a model, else its sub-folders that are models (sorted)."""
    if is_model_dir(folder):
        return [folder]
    return sorted(p for p in folder.iterdir() if p.is_dir() and is_model_dir(p))


def read_model(folder: str | Path) -> SfmCloud:
    """Read the COLMAP model in ``folder`` (or its largest numbered sub-model); ``InputError`` if none."""
    import pycolmap

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"--colmap-model '{folder}': folder not found")
    found = model_dirs(folder)
    if not found:
        raise InputError(
            f"--colmap-model '{folder}': no COLMAP model here (need cameras, images and points3D as .bin "
            "or .txt, in the folder or in a numbered sub-folder such as sparse/0)"
        )
    recs = []
    for d in found:
        try:
            recs.append(pycolmap.Reconstruction(str(d)))
        except Exception as exc:  # pycolmap raises plain RuntimeErrors/ValueErrors from C++
            raise InputError(f"--colmap-model '{d}': cannot read the COLMAP model ({_first_line(exc)})") from None
    rec = max(recs, key=lambda r: (r.num_reg_images(), r.num_points3D()))
    cloud = from_reconstruction(rec)
    if cloud.stats["registered"] < 2 or len(cloud.points) < 3:
        raise InputError(
            f"--colmap-model '{folder}': the model has {cloud.stats['registered']} registered images and "
            f"{len(cloud.points)} points; need at least 2 images and 3 points"
        )
    return cloud


def _first_line(exc: Exception) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return lines[-1] if lines else type(exc).__name__
