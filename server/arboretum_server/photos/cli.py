"""``arboretum photos``: photographs of a tree (or a COLMAP model) to a Z-up scan ready for ``decompose``.

    arboretum photos IMAGES_DIR --out scan.ply [--height 0.8] [--matcher auto|exhaustive|sequential]
        [--max-image-size 1600] [--max-features 8192] [--dense auto|never|always] [--work DIR]
        [--keep-ground] [--seed 0] [--verbose] [--json]
    arboretum photos --colmap-model sparse/0 --out scan.ply [--height 0.8] [--json]
"""

from __future__ import annotations

import argparse
import os
import time

from arboretum_library.checks import check_seed
from arboretum_library.cli import add_json_flag, emit

COLMAP_MAX_SEED = 2 ** 31 - 1
"""COLMAP's seeds are C ints: pycolmap refuses a larger ``random_seed`` with a TypeError."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("photos", help="photographs of a tree to a point cloud (pycolmap SfM)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("images", nargs="?", metavar="IMAGES_DIR", help="folder of photographs (.jpg/.png/...)")
    p.add_argument("--out", required=True, metavar="SCAN.ply", help="output point cloud (.ply/.xyz/.npy)")
    p.add_argument("--height", type=float, default=0.8, metavar="METRES",
                   help="scale the tree to this height (default 0.8, as VRTree section 4.1)")
    p.add_argument("--colmap-model", metavar="DIR", help="import this COLMAP model instead of running SfM")
    p.add_argument("--matcher", choices=("auto", "exhaustive", "sequential"), default="auto",
                   help="image pairs to match (auto: exhaustive up to 60 images)")
    p.add_argument("--max-image-size", type=int, default=1600, metavar="PX", help="downscale longer side to PX")
    p.add_argument("--max-features", type=int, default=8192, metavar="N", help="SIFT features kept per image")
    p.add_argument("--dense", choices=("auto", "never", "always"), default="auto",
                   help="dense stereo (needs pycolmap with CUDA; auto: when present)")
    p.add_argument("--work", metavar="DIR", help="keep COLMAP's database and models here")
    p.add_argument("--keep-ground", action="store_true", help="write the oriented, scaled cloud uncut")
    p.add_argument("--seed", type=int, default=0, help="seed for COLMAP's and the plane fit's sampling")
    p.add_argument("--verbose", action="store_true", help="show COLMAP's own log")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from arboretum_library.pointio import write_points
    from arboretum_library.progress import StatusLine

    from .isolate import IsolateOptions, apply, isolate

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    _check_args(args)
    iso_opts = IsolateOptions(height=args.height, seed=args.seed)
    t0 = time.perf_counter()
    cloud = _cloud(args, StatusLine() if not args.json else (lambda *a: None))
    t_sfm = time.perf_counter() - t0
    iso = isolate(cloud.points, iso_opts, cloud.camera_up)
    if args.keep_ground:
        points, colors = apply(iso.T_out_in, cloud.points), cloud.colors
    else:
        points, colors = iso.points, cloud.colors[iso.index]
    if not str(args.out).lower().endswith(".ply"):
        colors = None  # only PLY carries colours
    write_points(args.out, points, colors=colors)
    data = {"out": str(args.out), "source": args.colmap_model or args.images, "points": len(points),
            "sfm": cloud.stats, "dense": cloud.dense, "isolate": iso.stats, "height_m": args.height,
            "T_out_in": iso.T_out_in.tolist(), "camera_centres_out": apply(iso.T_out_in, cloud.camera_centres).tolist(),
            "image_names": list(cloud.image_names),
            "seconds": {"sfm": t_sfm, "total": time.perf_counter() - t0}}
    emit(args, data, _text(data))
    return 0


def _check_args(args: argparse.Namespace) -> None:
    """InputError naming the option for a mistake, before any image is read or COLMAP started."""
    from arboretum_library.errors import InputError
    from arboretum_library.outputs import check_output
    from arboretum_library.pointio import WRITERS

    if (args.images is None) == (args.colmap_model is None):
        raise InputError("give either IMAGES_DIR or --colmap-model DIR (one of them)")
    check_seed(args.seed)
    if args.images is not None and args.seed > COLMAP_MAX_SEED:
        raise InputError(f"--seed must be at most {COLMAP_MAX_SEED} (COLMAP's largest), got {args.seed}")
    check_output(args.out, "--out", suffixes=tuple(WRITERS))


def _cloud(args: argparse.Namespace, progress):
    if args.colmap_model is not None:
        from .colmap_import import read_model

        return read_model(args.colmap_model)
    from .reconstruct import ReconstructOptions, reconstruct

    opts = ReconstructOptions(matcher=args.matcher, max_image_size=args.max_image_size,
                              max_features=args.max_features, dense=args.dense,
                              seed=args.seed, verbose=args.verbose)
    return reconstruct(args.images, opts, work=args.work, progress=progress)


def _text(d: dict) -> str:
    s, i = d["sfm"], d["isolate"]
    kind = "dense" if d["dense"] else "sparse"
    lines = [
        f"{d['source']}: {s['registered']}/{s['images']} images registered, {s['points']} {kind} points, "
        f"reprojection error {s['mean_reprojection_error_px']:.2f} px",
        f"tree: {i['kept']} points kept ({i['ground_points']} ground points, up from {i['up_source']}), "
        f"scaled to {d['height_m']} m",
        f"wrote {d['points']} points to {d['out']} in {d['seconds']['total']:.1f} s",
    ]
    if not s.get("cuda", True) and not d["dense"]:
        lines.append("note: no CUDA in this pycolmap, so no dense stereo: the cloud is sparse")
    return "\n".join(lines)
