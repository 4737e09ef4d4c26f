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

MODELS = ("guiding", "harmonic")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "synth",
        help="grow a synthetic tree (guiding vectors or harmonic model) and scan it virtually",
        description="Grow a synthetic tree with ground truth and sample a labelled virtual scan of it.",
    )
    p.add_argument(
        "--model", choices=MODELS, default="guiding", help="tree model (default: guiding)"
    )
    p.add_argument(
        "--species", default="default", help="species or preset name (see docs/synthetic.md)"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="random seed: the same seed gives the same tree"
    )
    p.add_argument(
        "--points", type=int, default=12_000, help="point budget of the scan (default 12000)"
    )
    p.add_argument("--out", type=Path, required=True, help="scan to write (.ply, .xyz or .npy)")
    p.add_argument("--truth", type=Path, help="ground truth to write (.npz)")
    p.add_argument("--mesh", type=Path, help="the true tree as a mesh: .glb (textured), .obj or .ply")
    p.add_argument("--lod", type=int, default=0, help="level of detail of --mesh: 0 full, 1, 2, ... coarser")
    p.add_argument("--leaf-off", action="store_true", help="scan without leaves")
    p.add_argument("--missing-sector", type=float, default=0.0, metavar="DEG",
                   help="drop the points in an azimuth wedge this many degrees wide")  # fmt: skip
    p.add_argument(
        "--scanners", type=int, default=4, help="scanner stations around the tree (default 4)"
    )
    p.add_argument(
        "--noise", type=float, default=0.003, help="range noise sigma in metres (default 0.003)"
    )
    p.add_argument("--nodes", type=int, help="guiding model: graph node count (default per preset)")
    add_json_flag(p)
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    if args.points < 1:
        raise InputError(f"--points: must be >= 1, got {args.points}")
    if args.scanners < 1:
        raise InputError(f"--scanners: must be >= 1, got {args.scanners}")
    if not 0 <= args.missing_sector < 360:
        raise InputError(
            f"--missing-sector: must be in [0, 360) degrees, got {args.missing_sector}"
        )
    if args.noise < 0:
        raise InputError(f"--noise: must be >= 0, got {args.noise}")
    if args.nodes is not None and args.nodes < 500:
        raise InputError(f"--nodes: must be >= 500, got {args.nodes}")
    if args.mesh is not None and args.mesh.suffix.lower() not in (".glb", ".obj", ".ply"):
        raise InputError(f"--mesh {args.mesh}: write .glb, .obj or .ply")
    for flag, path in (("--out", args.out), ("--truth", args.truth), ("--mesh", args.mesh)):
        if path is not None and not path.parent.resolve().is_dir():
            raise InputError(f"{flag} {path}: folder '{path.parent}' does not exist")
    if args.truth is not None and args.truth.suffix.lower() != ".npz":
        raise InputError(f"--truth {args.truth}: the ground truth is written as .npz")


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
    t2 = time.perf_counter()
    write_points(args.out, cloud.points, labels=cloud.labels, branch_ids=cloud.branch_ids)
    if args.truth is not None:
        save_truth(args.truth, truth)
    triangles = None
    if args.mesh is not None:
        from arboretum_server.grow.writers import write_mesh
        from arboretum_server.mesh.lod import LodOptions
        from arboretum_server.mesh.scene import truth_mesh

        mesh = truth_mesh(truth, LodOptions(level=args.lod))
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
