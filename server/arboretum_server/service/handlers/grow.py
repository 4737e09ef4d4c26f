"""Growth of the assembled tree (VRTree 3.5, Eq. 2) as a job: ``grow.tree.grow_tree`` in a worker."""

from __future__ import annotations

import dataclasses

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import InputError
from arboretum_library.model import HBL
from arboretum_server.assembly.world import assembly_to_hbl
from arboretum_server.service.context import Context
from arboretum_server.service.jobs import Job


def grow_options(options: dict):
    """``GrowOptions`` from a request's option map; ``InputError`` for unknown names."""
    from arboretum_server.grow.options import GrowOptions

    known = {f.name for f in dataclasses.fields(GrowOptions)}
    bad = sorted(set(options) - known)
    if bad:
        raise InputError(f"unknown growth option(s): {', '.join(bad)}")
    opts = dict(options)
    if "lobe_density" in opts:
        opts["lobe_density"] = {int(k): float(v) for k, v in dict(opts["lobe_density"]).items()}
    try:
        return GrowOptions(**opts)
    except TypeError as exc:
        raise InputError(f"growth options: {exc}") from None


def checked_options(options: dict):
    """``GrowOptions`` from a request's or a script's ``options`` once their densities are within the
    limits of ``arboretum grow`` (``InputError`` otherwise)."""
    from arboretum_library.checks import check_number
    from arboretum_server.grow.limits import MAX_DENSITY, MAX_LEAF_DENSITY

    opts = grow_options(options)
    check_number(opts.density, "growth option density", 0.0, MAX_DENSITY, lo_open=True)
    check_number(opts.leaf_density, "growth option leaf_density", 0.0, MAX_LEAF_DENSITY)
    return opts


def checked_growth(ctx: Context, session_id: str, seed: int, options: dict, lod: int = 0) -> HBL:
    """The session's assembled HBL once ``seed``, ``lod`` and the growth ``options`` are ones a worker
    can grow without exhausting memory (the same limits as ``arboretum grow``: an assemble script's
    export with density 1000 wrote 258 MB, and a negative seed was an internal error)."""
    from arboretum_library.checks import check_seed
    from arboretum_server.grow.limits import check_size
    from arboretum_server.mesh.lod import check_lod

    check_seed(seed, "seed")
    check_lod(lod)
    opts = checked_options(options)
    hbl = session_hbl(ctx, session_id)
    check_size(hbl.lobes, opts)
    return hbl


def grow_job(progress, hbl: HBL, seed: int, options: dict) -> dict:
    """Worker: grow ``hbl``; the tree's arrays."""
    from arboretum_server.grow.tree import grow_tree

    t = grow_tree(hbl, grow_options(options), np.random.default_rng(seed), progress)
    return {"positions": t.positions, "parents": t.parents, "radii": t.radii, "levels": t.levels,
            "leaf_centres": t.leaves.centres, "leaf_normals": t.leaves.normals, "leaf_sizes": t.leaves.sizes}


def session_hbl(ctx: Context, session_id: str) -> HBL:
    """The assembled HBL of a session (checked now, grown in the worker)."""
    return assembly_to_hbl(ctx.sessions.get(session_id).history.assembly, ctx.example)


def grow(ctx: Context, req: P.Grow) -> Job:
    kwargs = {"hbl": checked_growth(ctx, req.session, req.seed, req.options), "seed": req.seed,
              "options": req.options}
    return Job(f"{__name__}:grow_job", kwargs, lambda r: P.GrownTree(**r))


HANDLERS = {P.Grow: grow}
