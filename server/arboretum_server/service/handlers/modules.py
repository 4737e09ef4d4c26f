"""Export as modules (Takikawa et al. 2025, ``arboretum_server.modules``) as a job: the assembled tree's
lobe hulls make the crown, the default module set grows in it, and the placed module instances are
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

    from arboretum_server.modules.crown import crown_from_meshes
    from arboretum_server.modules.export import from_modular_tree, write_instances
    from arboretum_server.modules.grow import grow_modular_tree
    from arboretum_server.modules.procedural import make_default_module_set

    if not hbl.lobes:
        raise InputError("export modules: the assembled tree has no lobes to make a crown from")
    rng = np.random.default_rng(seed)
    progress(0, 3, "crown")
    crown = crown_from_meshes([(lb.hull_vertices, lb.hull_faces) for lb in hbl.lobes])
    modules = make_default_module_set(rng)
    progress(1, 3, "growing modules")
    T = np.eye(4)
    T[:3, 3] = hbl.root
    tree = grow_modular_tree(modules, crown, module_options(options), rng, T_world_trunk=T)
    progress(2, 3, "writing")
    suffix, plain = FORMATS[format]
    name = f"tree-modules{suffix}"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        write_instances(path, from_modular_tree(tree, modules), plain=plain)
        data = path.read_bytes()
    progress(3, 3, "done")
    stats = {"instances": int(len(tree.module)), "types": int(tree.stats.types_used),
             "reached_fraction": float(tree.stats.reached_fraction)}
    return {"name": name, "data": np.frombuffer(data, np.uint8), "stats": stats}


def export_modules(ctx: Context, req: P.ExportModules) -> Job:
    if req.format not in FORMATS:
        raise InputError(f"export modules format {req.format!r}: use one of {', '.join(FORMATS)}")
    module_options(req.options)
    kwargs = {"hbl": session_hbl(ctx, req.session), "seed": req.seed, "options": req.options, "format": req.format}
    return Job(f"{__name__}:export_modules_job", kwargs, lambda r: P.ExportFile(**r))


HANDLERS = {P.ExportModules: export_modules}
