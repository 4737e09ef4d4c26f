"""``arboretum grow HBL_NPZ --out tree.glb``: grow twigs and leaves in the lobes, mesh, export."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output

MESH_FORMATS = (".glb", ".obj", ".ply")
SKELETON_FORMATS = (".json", ".ply")
MAX_DENSITY = 20.0
"""Largest --density: ten times the densest setting we use (2.1 in the bench). Memory and time grow
about linearly with it (docs/growth.md: about 0.7 GB and 5 s at 20 on a 40-lobe scan)."""
MAX_LEAF_DENSITY = 20.0
"""Largest --leaf-density (leaf cards per tip node, default 1): about 0.4 GB at 20 on a 40-lobe scan."""
MAX_STEP_REFINE = 4.0
"""Smallest --step: the default step (1/6 of the median lobe radius) divided by this (64 times as many
attraction points; at /5 a 40-lobe scan grew 608,181 twig nodes in 67 s and 2.8 GB)."""
MAX_ELEMENTS = 1_500_000
"""Largest estimated twig nodes + leaf cards (``estimate_size``): about 120 times the default growth
of a 40-lobe scan, 3.3-6 GB of memory at the measured 2.2-4 KB each (docs/growth.md, "Limits of the
options")."""
BYTES_PER_ELEMENT = 3000
"""Peak memory per twig node or leaf card, growth through GLB (measured 2.2-4 KB), for the message."""
LEAF_SHARE = 0.7
"""Share of twig nodes that bear leaves, an upper estimate (measured 0.50-0.67)."""


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
                   help="leaf card length in metres (default: 1.2 x step)")
    p.add_argument("--branch-radii", choices=("auto", "hbl", "pipe"), default="auto",
                   help="hbl: keep the HBL's branch radii and fit twigs under them; pipe: pipe model from "
                        "every tip to the root; auto (default): hbl when the HBL's radii are consistent")
    p.add_argument("--seed", type=int, default=0, help="random seed, >= 0 (same seed, same tree)")
    p.add_argument("--lod", type=int, default=0, help="level of detail: 0 full, 1, 2, ... 16 coarsest")
    p.add_argument("--sides", type=int, default=8, help="tube sides at LOD 0, 3 to 64 (default 8)")
    p.add_argument("--skeleton", default=None, help="also write the skeleton with radii: .json or .ply")
    add_json_flag(p)
    p.set_defaults(func=run)


def check_seed(seed: int, what: str = "--seed") -> None:
    """``InputError`` unless ``seed`` is a non-negative integer (what numpy's generators take)."""
    if seed < 0:
        raise InputError(f"{what} must not be negative, got {seed}")


def check_input_file(path: str, what: str) -> Path:
    """``path`` as a Path when it names an existing file; ``InputError`` naming ``what`` otherwise."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{what} {p}: is a folder, not a file")
    if not p.is_file():
        raise InputError(f"{what} {p}: no such file")
    return p


def check_lod(level: int, sides: int | None = None) -> None:
    """``InputError`` unless ``--lod level`` (and ``--sides sides``) are ones the mesher takes."""
    from arboretum_server.mesh.lod import MAX_LEVEL, SIDES_RANGE

    if not 0 <= level <= MAX_LEVEL:
        raise InputError(f"--lod must be 0 (full detail) to {MAX_LEVEL} (coarsest), got {level}")
    lo, hi = SIDES_RANGE
    if sides is not None and not lo <= sides <= hi:
        raise InputError(f"--sides must be {lo} to {hi}, got {sides}")


def check_number(value: float | None, what: str, lo: float, hi: float, lo_open: bool = False) -> None:
    """``InputError`` unless ``value`` (None: the default) is a finite number in [lo, hi] ((lo, hi]
    when ``lo_open``)."""
    if value is None:
        return
    low_ok = value > lo if lo_open else value >= lo
    if not (math.isfinite(value) and low_ok and value <= hi):
        low = f"> {lo:g}" if lo_open else f">= {lo:g}"
        raise InputError(f"{what} must be a number {low} and <= {hi:g}, got {value}")


def _check_args(args: argparse.Namespace) -> tuple[Path, Path | None]:
    """Every argument checked before any work: the output paths, then the numbers."""
    check_input_file(args.hbl, "HBL_OR_ASSEMBLY")
    out = Path(args.out)
    if out.suffix.lower() not in MESH_FORMATS:
        raise InputError(f"--out {out}: unknown format {out.suffix!r}; use one of {', '.join(MESH_FORMATS)}")
    skel = Path(args.skeleton) if args.skeleton else None
    if skel is not None and skel.suffix.lower() not in SKELETON_FORMATS:
        raise InputError(f"--skeleton {skel}: unknown format {skel.suffix!r}; use .json or .ply")
    check_output(out, "--out", inputs=[args.hbl], suffixes=MESH_FORMATS)
    if skel is not None:
        check_output(skel, "--skeleton", inputs=[args.hbl], outputs=[out], suffixes=SKELETON_FORMATS)
    check_seed(args.seed)
    check_lod(args.lod, args.sides)
    check_number(args.density, "--density", 0.0, MAX_DENSITY, lo_open=True)
    check_number(args.leaf_density, "--leaf-density", 0.0, MAX_LEAF_DENSITY)
    check_number(args.step, "--step", 0.0, math.inf, lo_open=True)
    check_number(args.leaf_size, "--leaf-size", 0.0, math.inf, lo_open=True)
    return out, skel


def check_step(step: float | None, lobes) -> str | None:
    """``InputError`` when ``--step`` is finer than the default step (1/6 of the median lobe radius)
    over ``MAX_STEP_REFINE``, or larger than every lobe; a note (str) when it exceeds the median lobe
    radius (most lobes then grow nothing); None otherwise."""
    from .attraction import default_step, equivalent_radius

    if step is None or not lobes:
        return None
    d0 = default_step(lobes)
    radii = [equivalent_radius(lb) for lb in lobes]
    if step < d0 / MAX_STEP_REFINE:
        raise InputError(f"--step {step:g} m is too fine for these lobes: the smallest is "
                         f"{d0 / MAX_STEP_REFINE:.3g} m (the default {d0:.3g} m / {MAX_STEP_REFINE:g})")
    if step > max(radii):
        raise InputError(f"--step {step:g} m is larger than every lobe (the largest has radius "
                         f"{max(radii):.3g} m): no twig would grow; the default is {d0:.3g} m")
    if step > 6 * d0:
        return (f"note: --step {step:g} m is larger than half the lobes (median radius {6 * d0:.3g} m); "
                "few twigs will grow")
    return None


def estimate_size(lobes, opts) -> tuple[int, int]:
    """(twig nodes, leaf cards) a growth with ``opts`` will make at most, about: one twig node per
    attraction point (``attraction.attraction_points``' count; measured 0.5-1.1), ``LEAF_SHARE`` of
    them bearing ``leaf_density`` cards."""
    import numpy as np

    from .attraction import default_step
    from .hulls import mesh_volume

    if not lobes:
        return 0, 0
    step = opts.step if opts.step is not None else default_step(lobes)
    hull = np.array([len(lb.hull_vertices) for lb in lobes], np.float64)
    volume = np.array([mesh_volume(lb.hull_vertices, lb.hull_faces) for lb in lobes])
    mult = np.array([opts.lobe_multiplier(i) for i in range(len(lobes))])
    cap = np.maximum(opts.max_points_per_lobe - hull, 0)
    interior = np.minimum(np.round(opts.attraction_density * mult * volume / step**3), cap)
    nodes = int((interior + hull)[mult > 0].sum())
    return nodes, int(LEAF_SHARE * opts.leaf_density * nodes)


def check_size(lobes, opts) -> None:
    """``InputError`` naming the estimate when the tree would exceed ``MAX_ELEMENTS``."""
    nodes, leaves = estimate_size(lobes, opts)
    if nodes + leaves > MAX_ELEMENTS:
        gb = (nodes + leaves) * BYTES_PER_ELEMENT / 1e9
        raise InputError(f"--density {opts.density:g}, --leaf-density {opts.leaf_density:g} and --step "
                         f"{opts.step if opts.step is not None else 'default'} would grow about {nodes:,} twig "
                         f"nodes and {leaves:,} leaf cards (about {gb:.0f} GB of memory), over the limit of "
                         f"{MAX_ELEMENTS:,} together; lower --density or --leaf-density, or raise --step")


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
        "twig_nodes": tree.twig_count, "leaves": int(len(mesh.leaves.faces) // 2),
        "bark_triangles": int(len(mesh.bark.faces)), "triangles": mesh.triangles,
        "trunk_radius": float(tree.radii[0]),
        "timing_s": {"grow": t1 - t0, "mesh": t2 - t1, "write": t3 - t2},
    }
    emit(args, data, f"wrote {out} ({size} bytes): {tree.twig_count} twig nodes, "
         f"{data['leaves']} leaf cards, {mesh.triangles} triangles" + (f"; skeleton {skel}" if skel else ""))
    return 0
