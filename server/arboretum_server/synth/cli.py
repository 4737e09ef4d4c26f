"""``arboretum synth``: grow a synthetic tree with ground truth and scan it virtually.

    arboretum synth --model guiding --species default --seed 1 --points 12000 \\
        --out scan.ply --truth truth.npz [--leaf-off] [--missing-sector 90] [--json]

The scan is a binary PLY with per-point ``label`` (0 wood, 1 leaf) and ``branch_id``; the truth is an
.npz read by ``arboretum_library.truth.load_truth``. Both files are written atomically.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output

MODELS = ("guiding", "harmonic")
MESH_FORMATS = (".glb", ".obj", ".ply")
MAX_NOISE = 1.0
"""Largest --noise (range noise sigma, metres): over 300 times the default 3 mm of a terrestrial
scanner; larger values blur a tree past recognition."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "synth",
        help="grow a synthetic tree (guiding vectors or harmonic model) and scan it virtually",
        description="Grow a synthetic tree with ground truth and sample a labelled virtual scan of it.",
    )
    p.add_argument(
        "--model", choices=MODELS, default="guiding", help="tree model (default: guiding)"
    )
    p.add_argument(  # None: 'default' for the guiding model; the harmonic model needs a name
        "--species", default=None, help="species or preset name (see docs/synthetic.md)"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="random seed, >= 0: the same seed gives the same tree"
    )
    p.add_argument(
        "--points", type=int, default=12_000, help="point budget of the scan, >= 200 (default 12000)"
    )
    p.add_argument("--out", type=Path, required=True, help="scan to write (.ply, .xyz or .npy)")
    p.add_argument("--truth", type=Path, help="ground truth to write (.npz)")
    p.add_argument("--mesh", type=Path, help="the true tree as a mesh: .glb (textured), .obj or .ply")
    p.add_argument("--lod", type=int, default=None, help="level of detail of --mesh: 0 full, 1, 2, ... 16 coarsest")
    p.add_argument("--leaf-off", action="store_true", help="scan without leaves")
    p.add_argument("--missing-sector", type=float, default=0.0, metavar="DEG",
                   help="drop the points in an azimuth wedge this many degrees wide")  # fmt: skip
    p.add_argument(
        "--scanners", type=int, default=4, help="scanner stations around the tree (default 4)"
    )
    p.add_argument(
        "--noise", type=float, default=0.003, help="range noise sigma in metres, 0 to 1 (default 0.003)"
    )
    p.add_argument("--nodes", type=int, help="guiding model: graph node count (default per preset)")
    add_json_flag(p)
    p.set_defaults(func=run)


MAX_NODES = 2_000_000
"""Largest guiding-model graph (the paper's trees: 150,000 nodes; 100,000,000 took 18.7 GB in 60 s)."""
MAX_SCANNERS = 64
"""Most scanner stations (the default is 4; 100,000 ran for minutes)."""
MAX_POINTS = 5_000_000
"""Most scan points (the sweeps use 40,000; the decomposition keeps 12,000)."""


def _check(args: argparse.Namespace) -> None:
    """Every argument checked before any work: the model's options, numbers, then the output paths."""
    from arboretum_library.checks import check_number, check_seed
    from arboretum_library.pointio import WRITERS
    from arboretum_server.mesh.lod import check_lod

    _check_model_options(args)
    min_points = min_scan_points()
    if args.points < min_points:
        raise InputError(f"--points: must be >= {min_points} (the fewest 'arboretum decompose' takes), "
                         f"got {args.points}")
    if args.points > MAX_POINTS:
        raise InputError(f"--points: at most {MAX_POINTS:,}, got {args.points:,}")
    if not 1 <= args.scanners <= MAX_SCANNERS:
        raise InputError(f"--scanners: must be 1..{MAX_SCANNERS}, got {args.scanners}")
    if not 0 <= args.missing_sector < 360:
        raise InputError(
            f"--missing-sector: must be in [0, 360) degrees, got {args.missing_sector}"
        )
    check_number(args.noise, "--noise", 0.0, MAX_NOISE)
    if args.nodes is not None and not 500 <= args.nodes <= MAX_NODES:
        raise InputError(f"--nodes: must be 500..{MAX_NODES:,}, got {args.nodes:,}")
    check_seed(args.seed)
    check_lod(args.lod or 0)
    if args.mesh is not None and args.mesh.suffix.lower() not in MESH_FORMATS:
        raise InputError(f"--mesh {args.mesh}: write .glb, .obj or .ply")
    if args.truth is not None and args.truth.suffix.lower() != ".npz":
        raise InputError(f"--truth {args.truth}: the ground truth is written as .npz")
    check_output(args.out, "--out", suffixes=tuple(WRITERS))
    if args.truth is not None:
        check_output(args.truth, "--truth", outputs=[args.out], suffixes=(".npz",))
    if args.mesh is not None:
        check_output(args.mesh, "--mesh", outputs=[args.out, args.truth], suffixes=MESH_FORMATS)
        from arboretum_server.grow.writers import check_obj_sidecars

        check_obj_sidecars(args.mesh)


def _check_model_options(args: argparse.Namespace) -> None:
    """Refuse options that would do nothing; fill in the guiding model's default species."""
    if args.model == "harmonic":
        from .harmonic import SPECIES

        if args.species is None:
            raise InputError(f"--model harmonic needs --species NAME, one of: {', '.join(sorted(SPECIES))}")
        if args.nodes is not None:
            raise InputError(f"--nodes {args.nodes}: sets the guiding model's graph; the harmonic model has none")
    elif args.species is None:
        args.species = "default"
    if args.lod is not None and args.mesh is None:
        raise InputError(f"--lod {args.lod}: sets the level of detail of --mesh; give --mesh too")


def min_scan_points() -> int:
    """The fewest points a scan may hold: what ``arboretum decompose`` takes (``min_points``)."""
    from arboretum_server.decompose.options import DecomposeOptions

    return DecomposeOptions().min_points


def _check_kept(args: argparse.Namespace, kept: int) -> None:
    """``InputError`` when occlusion, --leaf-off or --missing-sector left too few points to decompose."""
    if kept < min_scan_points():
        why = ["occlusion"] + (["--leaf-off"] if args.leaf_off else []) + (
            [f"--missing-sector {args.missing_sector:g}"] if args.missing_sector else [])
        raise InputError(f"--points {args.points}: the scan kept only {kept} points ({', '.join(why)}); "
                         f"'arboretum decompose' needs {min_scan_points()}: ask for more --points")


def grow(model: str, species: str, seed: int, nodes: int | None = None, progress=None):
    """The ``TreeTruth`` of ``model``/``species`` grown from ``seed`` (``InputError`` for bad names)."""
    if model == "guiding":
        from .guiding import grow_guiding
        from .presets import PRESETS, preset

        if species not in PRESETS:
            raise InputError(
                f"--species {species!r}: unknown guiding preset (known: {', '.join(sorted(PRESETS))})"
            )
        opts = preset(species) if nodes is None else preset(species, nodes=nodes)
        kwargs = {} if progress is None else {"progress": progress}
        return grow_guiding(opts, seed, species, **kwargs)
    from .harmonic import SPECIES, grow_species

    if species not in SPECIES:
        names = ", ".join(sorted(SPECIES))
        raise InputError(f"--species {species!r}: unknown harmonic species (known: {names})")
    return grow_species(species, seed)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from arboretum_library.pointio import write_points
    from arboretum_library.progress import StatusLine
    from arboretum_library.truth import save_truth

    from .scanner import ScanOptions, scan

    _check(args)
    t0 = time.perf_counter()
    truth = grow(
        args.model, args.species, args.seed, args.nodes, None if args.json else StatusLine()
    )
    t1 = time.perf_counter()
    opts = ScanOptions(points=args.points, scanners=args.scanners, noise=args.noise,
                       leaf_off=args.leaf_off, missing_sector=args.missing_sector)  # fmt: skip
    cloud = scan(truth, opts, np.random.default_rng([args.seed, 1]))
    _check_kept(args, len(cloud.points))
    t2 = time.perf_counter()
    write_points(args.out, cloud.points, labels=cloud.labels, branch_ids=cloud.branch_ids)
    if args.truth is not None:
        save_truth(args.truth, truth)
    triangles = None
    if args.mesh is not None:
        from arboretum_server.grow.writers import write_mesh
        from arboretum_server.mesh.lod import LodOptions
        from arboretum_server.mesh.scene import truth_mesh

        mesh = truth_mesh(truth, LodOptions(level=args.lod or 0))
        write_mesh(args.mesh, mesh)
        triangles = mesh.triangles
    summary = {
        "model": args.model, "species": args.species, "seed": args.seed,
        "nodes": truth.node_count, "branches": truth.branch_count, "leaves": truth.leaf_count,
        "height": float(np.ptp(truth.positions[:, 2])),
        "points": len(cloud.points), "wood_points": int((cloud.labels == 0).sum()),
        "leaf_points": int((cloud.labels == 1).sum()), "out": str(args.out),
        "truth": None if args.truth is None else str(args.truth),
        "mesh": None if args.mesh is None else str(args.mesh), "mesh_triangles": triangles,
        "seconds": {"grow": round(t1 - t0, 3), "scan": round(t2 - t1, 3)},
    }  # fmt: skip
    text = (f"{args.model}/{args.species} seed {args.seed}: {truth.node_count} nodes, {truth.branch_count} branches, "
            f"{truth.leaf_count} leaves -> {len(cloud.points)} points ({summary['wood_points']} wood) in {args.out}")  # fmt: skip
    emit(args, summary, text)
    return 0
