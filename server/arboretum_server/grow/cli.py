"""``arboretum grow HBL_NPZ --out tree.glb``: grow twigs and leaves in the lobes, mesh, export."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from arboretum_library.checks import check_input_file, check_number, check_seed
from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output

from .limits import MAX_DENSITY, MAX_LEAF_DENSITY, check_size, check_step

MESH_FORMATS = (".glb", ".obj", ".ply")
SKELETON_FORMATS = (".json", ".ply")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "grow", help="grow twigs and leaves inside the lobes of an HBL and export the tree",
        description="Space colonization in every lobe (VRTree Eq. 2), pipe-model radii, leaf cards, "
        "then a mesh (.glb with textures, .obj + .mtl, or .ply) and optionally the skeleton.",
    )
    p.add_argument("hbl", metavar="HBL_OR_ASSEMBLY",
                   help="a record .npz: an HBL (e.g. from 'arboretum decompose --save-hbl') or an Assembly "
                   "(e.g. a session saved by 'arboretum assemble', with --library)")
    p.add_argument("--library", metavar="LIB", default=None,
                   help="the example library an Assembly record places examples from")
    p.add_argument("--out", required=True, help="mesh file to write: .glb, .obj or .ply")
    p.add_argument("--density", type=float, default=1.0, help="twig density multiplier, > 0 and <= 20 (default 1.0)")
    p.add_argument("--leaf-density", type=float, default=1.0, help="leaf cards per tip node, 0 to 20 (default 1.0)")
    p.add_argument("--step", type=float, default=None,
                   help="growth radius D in metres (default: 1/6 of the median lobe radius; at least a quarter of "
                        "that, at most the largest lobe's radius)")
    p.add_argument("--leaf-size", type=float, default=None,
                   help="leaf card length in metres (default: 1.2 x step); sets the size only, never the number "
                        "of cards: bigger cards hang from the same twigs and overhang the lobes by up to their "
                        "length")
    p.add_argument("--branch-radii", choices=("auto", "hbl", "pipe"), default="auto",
                   help="hbl: keep the HBL's branch radii and fit twigs under them; pipe: pipe model from "
                        "every tip to the root; auto (default): hbl when the HBL's radii are consistent")
    p.add_argument("--seed", type=int, default=0, help="random seed, >= 0 (same seed, same tree)")
    p.add_argument("--lod", type=int, default=0, help="level of detail: 0 full, 1, 2, ... 16 coarsest")
    p.add_argument("--sides", type=int, default=8, help="tube sides at LOD 0, 3 to 64 (default 8)")
    p.add_argument("--skeleton", default=None, help="also write the skeleton with radii: .json or .ply")
    add_json_flag(p)
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> tuple[Path, Path | None]:
    """Every argument checked before any work: the output paths, then the numbers."""
    from arboretum_server.mesh.lod import check_lod

    from .writers import check_obj_sidecars

    check_input_file(args.hbl, "HBL_OR_ASSEMBLY")
    out = Path(args.out)
    if out.suffix.lower() not in MESH_FORMATS:
        raise InputError(f"--out {out}: unknown format {out.suffix!r}; use one of {', '.join(MESH_FORMATS)}")
    skel = Path(args.skeleton) if args.skeleton else None
    if skel is not None and skel.suffix.lower() not in SKELETON_FORMATS:
        raise InputError(f"--skeleton {skel}: unknown format {skel.suffix!r}; use .json or .ply")
    check_output(out, "--out", inputs=[args.hbl], suffixes=MESH_FORMATS, libraries=[args.library])
    check_obj_sidecars(out)
    if skel is not None:
        check_output(skel, "--skeleton", inputs=[args.hbl], outputs=[out], suffixes=SKELETON_FORMATS,
                     libraries=[args.library])
    check_seed(args.seed)
    check_lod(args.lod, args.sides)
    check_number(args.density, "--density", 0.0, MAX_DENSITY, lo_open=True)
    check_number(args.leaf_density, "--leaf-density", 0.0, MAX_LEAF_DENSITY)
    check_number(args.step, "--step", 0.0, math.inf, lo_open=True)
    check_number(args.leaf_size, "--leaf-size", 0.0, math.inf, lo_open=True)
    return out, skel


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from arboretum_library.progress import StatusLine
    from arboretum_server.assembly.world import load_structure
    from arboretum_server.mesh.lod import LodOptions
    from arboretum_server.mesh.scene import tree_mesh

    from .options import GrowOptions
    from .tree import grow_tree
    from .writers import write_mesh, write_skeleton

    out, skel = _check_args(args)
    hbl = load_structure(args.hbl, args.library)
    note = check_step(args.step, hbl.lobes)
    opts = GrowOptions(density=args.density, leaf_density=args.leaf_density, step=args.step,
                       leaf_size=args.leaf_size, branch_radii=args.branch_radii)
    check_size(hbl.lobes, opts)
    if note:
        print(note, file=sys.stderr)
    t0 = time.perf_counter()
    tree = grow_tree(hbl, opts, np.random.default_rng(args.seed), StatusLine())
    t1 = time.perf_counter()
    mesh = tree_mesh(tree, LodOptions(sides=args.sides, level=args.lod))
    t2 = time.perf_counter()
    size = write_mesh(out, mesh)
    if skel is not None:
        write_skeleton(skel, tree)
    t3 = time.perf_counter()
    data = {
        "out": str(out), "bytes": size, "skeleton": str(skel) if skel else None,
        "seed": args.seed, "branches": len(hbl.branches), "lobes": len(hbl.lobes),
        "lod": args.lod, "step": tree.step, "iterations": tree.iterations, "nodes": len(tree.positions),
        "twig_nodes": tree.twig_count, "leaves": mesh.cards,
        "bark_triangles": int(len(mesh.bark.faces)), "triangles": mesh.triangles,
        "trunk_radius": float(tree.radii[0]),
        "timing_s": {"grow": t1 - t0, "mesh": t2 - t1, "write": t3 - t2},
    }
    emit(args, data, f"wrote {out} ({size} bytes): {tree.twig_count} twig nodes, "
         f"{data['leaves']} leaf cards, {mesh.triangles} triangles" + (f"; skeleton {skel}" if skel else ""))
    return 0
