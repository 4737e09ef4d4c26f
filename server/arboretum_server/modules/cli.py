"""``arboretum modules``: a modular tree in a crown (or converted from a grown tree) as instanced files.

    arboretum modules --crown crown.obj --out tree.glb           # grow in a closed mesh
    arboretum modules --assembly hbl.npz --out tree.usdc         # crown = union of the lobe hulls
    arboretum modules --tree hbl.npz --types 16 --out tree.glb   # grow twigs, cut into 16 module types
"""

from __future__ import annotations

import argparse
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output
from arboretum_library.pointio import UP_CHOICES

CROWN_FORMATS = (".obj", ".ply", ".glb", ".gltf")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "modules", help="build a modular tree and export it instanced (glTF, USD)",
        description="Grow a controllable modular tree (Takikawa et al. 2025) in a crown mesh or in an HBL's "
        "lobes, or convert a grown tree into K module types, and write it instanced: .glb with "
        "EXT_mesh_gpu_instancing (or plain nodes), .usdc/.usda with a UsdGeom.PointInstancer.",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--crown", metavar="MESH", help="closed crown mesh in metres: .obj (Y up unless its "
                     "header says Z up), .ply (Z up), .glb/.gltf (Y up); see --up")
    src.add_argument("--assembly", metavar="A", help="record .npz (HBL, or Assembly with --library): the "
                     "union of its lobe hulls is the crown, its main branch base the trunk position")
    src.add_argument("--tree", metavar="TREE", help="record .npz (HBL, or Assembly with --library): grown "
                     "with default options, then converted into --types module types")
    p.add_argument("--up", choices=UP_CHOICES, default="auto",
                   help="up axis of the --crown mesh: auto (default: the format's usual axis above, unless "
                        "its vertices surely stand along the other), y or z")
    p.add_argument("--modules-up", choices=UP_CHOICES, default="auto",
                   help="up axis of --modules files without Arboretum's header: auto (default: the format's "
                        "usual, OBJ Y up; pieces are never guessed from their shape), y or z")
    p.add_argument("--modules", metavar="DIR", default=None,
                   help="module folder (.obj/.glb; default assets/modules/default)")
    p.add_argument("--library", metavar="LIB", default=None, help="example library for an Assembly record")
    p.add_argument("--out", required=True, help="file to write: .glb, .usdc, .usda or .usd (a crate file)")
    p.add_argument("--plain-nodes", action="store_true",
                   help="glTF: one plain node per instance instead of EXT_mesh_gpu_instancing")
    p.add_argument("--types", type=int, default=None, metavar="K",
                   help="module types: clusters for --tree (default 16); first K branch modules otherwise")
    p.add_argument("--seed", type=int, default=0, help="random seed, >= 0 (same seed, same file)")
    add_json_flag(p)
    p.set_defaults(func=run)


def _crown_mesh(path: str, up: str = "auto"):
    from .meshio import load_mesh

    return load_mesh(path, "--crown", up)


def run(args: argparse.Namespace) -> int:
    import time

    from .export import flat_size, write_instances
    from .report import describe, size_report

    out = Path(args.out)
    suffix = _check_args(args)
    t0 = time.perf_counter()
    if args.tree:
        inst, extra = _converted(args)
    else:
        inst, extra = _grown(args)
    t1 = time.perf_counter()
    size = write_instances(out, inst, args.plain_nodes)
    data = {"out": str(out), "seed": args.seed, "plain_nodes": bool(args.plain_nodes),
            **size_report(inst, size, flat_size(inst, suffix)), **extra,
            "timing_s": {"build": t1 - t0, "write": time.perf_counter() - t1}}
    emit(args, data, describe(data))
    return 0


def _check_args(args: argparse.Namespace) -> str:
    """The input, the output path and the numbers, checked before any work; the output's suffix."""
    from arboretum_library.checks import check_input_file, check_seed

    from .export import check_format

    flag, source = next((f, v) for f, v in (("--crown", args.crown), ("--assembly", args.assembly),
                                            ("--tree", args.tree)) if v)
    src = Path(source)
    if flag == "--crown" and src.suffix.lower() not in CROWN_FORMATS:
        raise InputError(f"--crown {src}: unsupported format {src.suffix!r} (use {', '.join(CROWN_FORMATS)})")
    check_input_file(source, flag)
    check_output(args.out, "--out", inputs=[source], libraries=[args.library])
    suffix = check_format(args.out, args.plain_nodes)
    if args.modules_up != "auto" and args.modules is None:
        raise InputError("--modules-up applies to the files of --modules DIR only (the bundled set says its axis)")
    if flag == "--tree" and args.modules is not None:
        raise InputError("--modules applies to --crown and --assembly only (--tree makes its own module "
                         "types from the grown tree; set their number with --types)")
    if args.types is not None and args.types < 1:
        raise InputError("--types must be >= 1")
    check_seed(args.seed)
    return suffix


def _converted(args: argparse.Namespace):
    import numpy as np

    from arboretum_library.progress import StatusLine, no_progress
    from arboretum_server.assembly.world import load_structure
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree

    from .convert import ConvertOptions, convert_tree
    from .export import from_converted

    hbl = load_structure(args.tree, args.library)
    rng = np.random.default_rng(args.seed)
    tree = grow_tree(hbl, GrowOptions(), rng, no_progress if args.json else StatusLine())
    conv = convert_tree(tree, ConvertOptions(types=args.types or 16), rng)
    return from_converted(conv), {
        "source": "tree", "nodes": int(len(tree.positions)), "height": conv.height,
        "chamfer": conv.chamfer, "chamfer_fraction": conv.chamfer_fraction,
    }


def _grown(args: argparse.Namespace):
    import numpy as np

    from .export import from_modular_tree
    from .fit import crown_root, grow_in_crown, reach_note
    from .options import ModularTreeOptions
    from .report import constraint_report

    modules = _module_set(args.modules, args.types, args.modules_up)
    if args.crown:
        meshes = [_crown_mesh(args.crown, args.up)]
        root = crown_root(meshes[0][0])
    else:
        meshes, root = _assembly_crown(args.assembly, args.library)
    tree, scaled, k = grow_in_crown(modules, meshes, root, ModularTreeOptions(),
                                    np.random.default_rng(args.seed))
    note = reach_note(tree.stats.reached_fraction, tree.stats.modules_placed)
    return from_modular_tree(tree, scaled), {
        "source": "crown" if args.crown else "assembly", "module_scale": k,
        "constraints": constraint_report(tree), "notes": [note] if note else []}


def _assembly_crown(path: str, library: str | None):
    """The lobe hulls [(V, 3), (F, 3)] of the record at ``path`` and its trunk position (3,)."""
    from arboretum_server.assembly.world import load_structure

    from .fit import hbl_crown

    return hbl_crown(load_structure(path, library), f"--assembly {path}")


def _module_set(folder: str | None, types: int | None, up: str = "auto"):
    from .fit import default_module_set
    from .moduleset import load_module_set

    if folder is None:
        modules = default_module_set()
    elif not Path(folder).is_dir():
        raise InputError(f"--modules {folder}: not a folder")
    else:
        modules = load_module_set(folder, up)
    if types is None:
        return modules
    keep = [m.name for m in modules.modules if m.is_trunk]
    keep += [m.name for m in modules.modules if not m.is_trunk][:types]
    return modules.subset(keep)
