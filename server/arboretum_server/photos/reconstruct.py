"""Structure from motion with pycolmap: photographs of a tree to a (sparse or dense) point cloud.

Steps (each timed in ``SfmCloud.stats['timing_s']``): SIFT feature extraction on the CPU (one shared
camera, SIMPLE_RADIAL), matching (exhaustive for up to ``exhaustive_max`` images, else sequential with
the images in name order), incremental mapping (the model with the most registered images is kept).
The same photographs and seed give the same cloud: the images enter the database in name order before
the (threaded) extraction, whose threads would otherwise number them in the order they finish, and the
two-view RANSAC of geometric verification is seeded (COLMAP's default, -1, seeds it afresh each run).
Dense stereo (undistortion, patch-match stereo, fusion) needs pycolmap built with CUDA: with
``dense='auto'`` it runs only when ``cuda_available()``; on a CPU-only build the result is the sparse
cloud, which holds a few thousand points for two dozen photographs (see docs/photos.md).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from arboretum_library.errors import InputError
from arboretum_library.progress import ProgressFn, no_progress

from .colmap_import import SfmCloud, from_reconstruction

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp")
MIN_IMAGES = 3


@dataclass(frozen=True)
class ReconstructOptions:
    """How ``reconstruct`` runs COLMAP (SfM has no symbols in the VRTree paper; COLMAP's names)."""

    matcher: str = "auto"
    """'exhaustive' (every pair), 'sequential' (neighbours in name order), or 'auto' (exhaustive up to
    ``exhaustive_max`` images)."""
    exhaustive_max: int = 60
    """Largest image count matched exhaustively with ``matcher='auto'`` (the cost grows as n^2)."""
    sequential_overlap: int = 10
    """With sequential matching, each image is matched with this many following ones."""
    max_image_size: int = 1600
    """Images are downscaled so their longer side is at most this many pixels before SIFT."""
    max_features: int = 8192
    """SIFT features kept per image."""
    camera_model: str = "SIMPLE_RADIAL"
    """COLMAP camera model, one camera shared by every image (one phone or camera, fixed zoom)."""
    dense: str = "auto"
    """'auto' (dense stereo when CUDA is present), 'never', or 'always' (an error without CUDA)."""
    seed: int = 0
    """Seed of COLMAP's random sampling (two-view RANSAC in matching, mapping's RANSAC and initial pair
    trials)."""
    num_threads: int = -1
    """Threads for extraction, matching and mapping (-1: all cores)."""
    verbose: bool = False
    """Let COLMAP log its progress (INFO lines) to stderr; otherwise only its errors."""

    def __post_init__(self) -> None:
        if self.matcher not in ("auto", "exhaustive", "sequential"):
            raise InputError(f"matcher must be 'auto', 'exhaustive' or 'sequential', got {self.matcher!r}")
        if self.dense not in ("auto", "never", "always"):
            raise InputError(f"dense must be 'auto', 'never' or 'always', got {self.dense!r}")
        if self.max_image_size < 64:
            raise InputError(f"max image size must be at least 64 pixels, got {self.max_image_size}")
        if self.max_features < 16:
            raise InputError(f"max features must be at least 16, got {self.max_features}")


def cuda_available() -> bool:
    """True when the installed pycolmap was built with CUDA (dense stereo possible)."""
    import pycolmap

    return bool(getattr(pycolmap, "has_cuda", False))


def list_images(folder: str | Path) -> list[str]:
    """Sorted names of the image files in ``folder``; ``InputError`` if missing or too few."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"'{folder}': image folder not found")
    names = sorted(p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if len(names) < MIN_IMAGES:
        raise InputError(
            f"'{folder}': found {len(names)} image(s) ({', '.join(IMAGE_SUFFIXES)}); "
            f"structure from motion needs at least {MIN_IMAGES}, better 20 or more around the tree"
        )
    return names


def reconstruct(images: str | Path, options: ReconstructOptions = ReconstructOptions(),
                work: str | Path | None = None, progress: ProgressFn = no_progress) -> SfmCloud:
    """Reconstruct the photographs in folder ``images`` into points and cameras (COLMAP's frame).

    ``work`` keeps COLMAP's database and models there (default: a temporary folder, removed after).
    Raises ``InputError`` when the images are unusable or no model could be built from them.
    """
    names = list_images(images)
    use_dense = _dense_wanted(options)
    if work is not None:
        Path(work).mkdir(parents=True, exist_ok=True)
        return _run(Path(images), names, Path(work), options, use_dense, progress)
    with tempfile.TemporaryDirectory(prefix="arboretum-sfm-") as tmp:
        return _run(Path(images), names, Path(tmp), options, use_dense, progress)


def _dense_wanted(o: ReconstructOptions) -> bool:
    if o.dense == "never":
        return False
    if cuda_available():
        return True
    if o.dense == "always":
        raise InputError("dense stereo needs pycolmap built with CUDA; this pycolmap has no CUDA "
                         "(use the sparse cloud, or run on a machine with an NVIDIA GPU)")
    return False


def _run(images: Path, names: list[str], work: Path, o: ReconstructOptions, dense: bool,
         progress: ProgressFn) -> SfmCloud:
    import pycolmap

    pycolmap.set_random_seed(o.seed)
    pycolmap.logging.minloglevel = 0 if o.verbose else 2
    db = work / "database.db"
    db.unlink(missing_ok=True)
    steps = 4 if dense else 3
    timing: dict[str, float] = {}
    t = time.perf_counter()
    progress(0, steps, "photos: extracting features")
    _extract(db, images, names, o)
    timing["features"], t = time.perf_counter() - t, time.perf_counter()
    progress(1, steps, "photos: matching")
    matcher = _matcher(o, len(names))
    _match(db, o, matcher)
    timing["matching"], t = time.perf_counter() - t, time.perf_counter()
    progress(2, steps, "photos: mapping")
    rec = _map(db, images, work / "sparse", o, len(names))
    timing["mapping"], t = time.perf_counter() - t, time.perf_counter()
    cloud = from_reconstruction(rec, images_total=len(names))
    if dense:
        progress(3, steps, "photos: dense stereo (CUDA)")
        cloud = _densify(cloud, rec, images, work)
        timing["dense"] = time.perf_counter() - t
    progress(steps, steps, "photos: done")
    stats = {**cloud.stats, "matcher": matcher, "dense": dense, "cuda": cuda_available(), "timing_s": timing}
    return SfmCloud(cloud.points, cloud.colors, cloud.camera_centres, cloud.camera_up, cloud.image_names,
                    cloud.errors, cloud.dense, stats)


def _matcher(o: ReconstructOptions, n: int) -> str:
    if o.matcher != "auto":
        return o.matcher
    return "exhaustive" if n <= o.exhaustive_max else "sequential"


def _extract(db: Path, images: Path, names: list[str], o: ReconstructOptions) -> None:
    import pycolmap

    ext = pycolmap.FeatureExtractionOptions()
    ext.max_image_size = o.max_image_size
    ext.num_threads = o.num_threads
    ext.sift.max_num_features = o.max_features
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = o.camera_model
    pycolmap.Database.open(str(db)).close()  # import_images wants the database to exist
    pycolmap.import_images(str(db), str(images), camera_mode=pycolmap.CameraMode.SINGLE, image_names=names,
                           options=reader)  # image ids in name order, whatever order extraction ends in
    pycolmap.extract_features(str(db), str(images), image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
                              reader_options=reader, extraction_options=ext, device=pycolmap.Device.cpu)


def _match(db: Path, o: ReconstructOptions, matcher: str) -> None:
    import pycolmap

    opts = pycolmap.FeatureMatchingOptions()
    opts.num_threads = o.num_threads
    verify = pycolmap.TwoViewGeometryOptions()
    verify.ransac.random_seed = o.seed  # -1 (the default) draws a new seed every run
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(str(db), matching_options=opts, verification_options=verify,
                                  device=pycolmap.Device.cpu)
    else:
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = o.sequential_overlap
        pycolmap.match_sequential(str(db), matching_options=opts, pairing_options=pairing,
                                  verification_options=verify, device=pycolmap.Device.cpu)


def _map(db: Path, images: Path, out: Path, o: ReconstructOptions, n_images: int):
    import pycolmap

    out.mkdir(parents=True, exist_ok=True)
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = o.num_threads
    opts.random_seed = o.seed
    opts.mapper.random_seed = o.seed
    opts.triangulation.random_seed = o.seed
    models = pycolmap.incremental_mapping(str(db), str(images), str(out), options=opts)
    if not models:
        raise InputError(
            f"'{images}': no 3D model could be built from {n_images} images (too few features matched "
            "between views: photograph the tree with more overlap, in focus, against a textured background)"
        )
    return max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()))


def _densify(sparse: SfmCloud, rec, images: Path, work: Path) -> SfmCloud:
    """Dense points by patch-match stereo and fusion (CUDA only); cameras as in ``sparse``."""
    import numpy as np
    import pycolmap

    model = work / "sparse-best"
    model.mkdir(exist_ok=True)
    rec.write(str(model))
    mvs = work / "dense"
    pycolmap.undistort_images(str(mvs), str(model), str(images))
    pycolmap.patch_match_stereo(str(mvs))
    fused = pycolmap.stereo_fusion(str(mvs / "fused.ply"), str(mvs))
    dense = from_reconstruction(fused)
    return SfmCloud(dense.points, dense.colors, sparse.camera_centres, sparse.camera_up, sparse.image_names,
                    np.zeros(0), True, {**sparse.stats, "points": len(dense.points)})
