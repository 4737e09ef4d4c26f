"""Export of the assembled tree as a job: grow, mesh, write (GLB, OBJ zipped with its MTL and
textures, or PLY) in a worker, and send the file's bytes back (no shared disk). Module export is in
``modules``."""

from __future__ import annotations

import io
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import InputError
from arboretum_library.model import HBL
from arboretum_server.service.context import Context
from arboretum_server.service.jobs import Job

from .grow import checked_growth, grow_options

FORMATS = ("glb", "obj", "ply")


def export_mesh_job(progress, hbl: HBL, format: str, seed: int, lod: int, options: dict) -> dict:
    """Worker: grow ``hbl``, mesh it at ``lod`` and return the file's name, bytes and counts."""
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.grow.writers import write_mesh
    from arboretum_server.mesh.lod import LodOptions
    from arboretum_server.mesh.scene import tree_mesh

    tree = grow_tree(hbl, grow_options(options), np.random.default_rng(seed), progress)
    mesh = tree_mesh(tree, LodOptions(level=lod))
    with tempfile.TemporaryDirectory(prefix="arboretum-export-") as tmp:
        path = Path(tmp) / f"tree.{format}"
        write_mesh(path, mesh)
        if format == "obj":
            buf = io.BytesIO()
            with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
                for f in sorted(Path(tmp).iterdir()):
                    z.write(f, f.name)
            name, data = "tree-obj.zip", buf.getvalue()
        else:
            name, data = path.name, path.read_bytes()
    stats = {"triangles": mesh.triangles, "twig_nodes": tree.twig_count, "leaves": mesh.cards}
    return {"name": name, "data": np.frombuffer(data, np.uint8), "stats": stats}


def export_mesh(ctx: Context, req: P.ExportMesh) -> Job:
    if req.format not in FORMATS:
        raise InputError(f"export format {req.format!r}: use one of {', '.join(FORMATS)}")
    kwargs = {"hbl": checked_growth(ctx, req.session, req.seed, req.options, req.lod), "format": req.format,
              "seed": req.seed, "lod": req.lod, "options": req.options}
    return Job(f"{__name__}:export_mesh_job", kwargs, lambda r: P.ExportFile(**r))


HANDLERS = {P.ExportMesh: export_mesh}
