"""Export as modules (Takikawa et al. 2025, ``arboretum_server.modules``) as a job: the assembled tree's
lobe hulls make the crown, the default module set (``assets/modules/default``, as ``arboretum modules``
uses) is scaled to it and grows in it from the same trunk placement as the CLI's (``modules.fit``:
``grow_in_crown``, the same tree for the same seed), and the placed module instances are
written by ``modules.export`` in the format asked for: ``glb`` (plain nodes sharing one mesh per module
type: every importer reads those), ``glb-instanced`` (EXT_mesh_gpu_instancing), ``usdc`` or ``usda``
(a UsdGeom.PointInstancer)."""

from __future__ import annotations

import dataclasses

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import InputError
from arboretum_library.model import HBL
from arboretum_server.service.context import Context
from arboretum_server.service.handlers.grow import session_hbl
from arboretum_server.service.jobs import Job

FORMATS = {"glb": (".glb", True), "glb-instanced": (".glb", False), "usdc": (".usdc", False), "usda": (".usda", False)}
"""Request format -> (file suffix, plain nodes)."""


def module_options(options: dict):
    """``ModularTreeOptions`` from a request's option map; ``InputError`` for unknown names."""
    from arboretum_server.modules.options import ModularTreeOptions

    bad = sorted(set(options) - {f.name for f in dataclasses.fields(ModularTreeOptions)})
    if bad:
        raise InputError(f"unknown module option(s): {', '.join(bad)}")
    try:
        return ModularTreeOptions(**options)
    except TypeError as exc:
        raise InputError(f"module options: {exc}") from None


def export_modules_job(progress, hbl: HBL, seed: int, options: dict, format: str = "glb") -> dict:
    """Worker: grow a modular tree in the crown of ``hbl``'s lobes; the file's name, bytes and counts."""
    import tempfile
    from pathlib import Path

    from arboretum_server.modules.export import from_modular_tree, write_instances
    from arboretum_server.modules.fit import (
        default_module_set,
        grow_in_crown,
        hbl_crown,
        reach_note,
    )

    meshes, root = hbl_crown(hbl, "export modules: the assembled tree")
    opts = module_options(options)
    progress(0, 3, "module set")
    modules = default_module_set()
    progress(1, 3, "growing modules")
    tree, modules, k = grow_in_crown(modules, meshes, root, opts, np.random.default_rng(seed))
    progress(2, 3, "writing")
    suffix, plain = FORMATS[format]
    name = f"tree-modules{suffix}"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        write_instances(path, from_modular_tree(tree, modules), plain=plain)
        data = path.read_bytes()
    progress(3, 3, "done")
    stats = {"instances": int(len(tree.module)), "types": int(tree.stats.types_used),
             "reached_fraction": float(tree.stats.reached_fraction), "module_scale": k,
             "notes": [n for n in [reach_note(tree.stats.reached_fraction, tree.stats.modules_placed)] if n]}
    return {"name": name, "data": np.frombuffer(data, np.uint8), "stats": stats}


def export_modules(ctx: Context, req: P.ExportModules) -> Job:
    if req.format not in FORMATS:
        raise InputError(f"export modules format {req.format!r}: use one of {', '.join(FORMATS)}")
    module_options(req.options)
    kwargs = {"hbl": session_hbl(ctx, req.session), "seed": req.seed, "options": req.options, "format": req.format}
    return Job(f"{__name__}:export_modules_job", kwargs, lambda r: P.ExportFile(**r))


HANDLERS = {P.ExportModules: export_modules}
