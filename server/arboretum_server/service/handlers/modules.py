"""Export as modules (Takikawa et al. 2025, ``arboretum_server.modules``) as a job: the assembled tree's
lobe hulls make the crown, the default module set grows in it, and the placed module instances are
written as a GLB of plain nodes sharing one mesh per module type (every importer reads those)."""

from __future__ import annotations

import dataclasses

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import InputError
from arboretum_library.model import HBL
from arboretum_server.service.context import Context
from arboretum_server.service.handlers.grow import session_hbl
from arboretum_server.service.jobs import Job

FORMATS = ("glb",)


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


def export_modules_job(progress, hbl: HBL, seed: int, options: dict) -> dict:
    """Worker: grow a modular tree in the crown of ``hbl``'s lobes; the GLB's name, bytes and counts."""
    from arboretum_library.export.gltf import glb_bytes
    from arboretum_library.export.parts import Material, MeshPart, Node
    from arboretum_server.modules.crown import crown_from_meshes
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
    parts = [MeshPart(m.name, m.vertices, m.faces) for m in modules.modules]
    nodes = [Node(int(k), T_k, f"module-{i}") for i, (k, T_k) in enumerate(zip(tree.module, tree.T_world_module))]
    data = glb_bytes(parts, [Material("bark", (0.35, 0.25, 0.17, 1.0))], nodes)
    progress(3, 3, "done")
    stats = {"instances": int(len(tree.module)), "types": int(tree.stats.types_used),
             "reached_fraction": float(tree.stats.reached_fraction)}
    return {"name": "tree-modules.glb", "data": np.frombuffer(data, np.uint8), "stats": stats}


def export_modules(ctx: Context, req: P.ExportModules) -> Job:
    if req.format not in FORMATS:
        raise InputError(f"export modules format {req.format!r}: use one of {', '.join(FORMATS)} (USD is not written yet)")
    module_options(req.options)
    kwargs = {"hbl": session_hbl(ctx, req.session), "seed": req.seed, "options": req.options}
    return Job(f"{__name__}:export_modules_job", kwargs, lambda r: P.ExportFile(**r))


HANDLERS = {P.ExportModules: export_modules}
