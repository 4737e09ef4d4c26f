"""Library operations: list, search, get, delete, and import a scan by decomposing it (a job)."""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Any

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import InputError
from arboretum_server.service.context import Context
from arboretum_server.service.jobs import Job


def _entry(e) -> dict:
    d = dataclasses.asdict(e)
    d.update(d.pop("descriptors"))
    d["tags"] = list(e.tags)
    return d


def list_examples(ctx: Context, req: P.LibraryList) -> P.LibraryEntries:
    filters = {"species": req.species} if req.species else {}
    rows = ctx.library().entries(tags=req.tags, **filters)
    return P.LibraryEntries(entries=tuple(_entry(e) for e in rows))


def search(ctx: Context, req: P.LibrarySearch) -> P.LibraryHits:
    hits = ctx.library().search(req.query, limit=max(req.limit, 0) or None)
    return P.LibraryHits(hits=tuple({"id": h.id, "score": h.score, "matched": list(h.matched)} for h in hits))


def get(ctx: Context, req: P.LibraryGet) -> P.LibraryExample:
    return P.LibraryExample(example=ctx.example(req.id))


def delete(ctx: Context, req: P.LibraryDelete) -> P.Ack:
    ctx.library().delete(req.id)
    ctx.forget(req.id)
    return P.Ack(detail=f"deleted {req.id}")


def options_from(species: str, options: dict) -> Any:
    """``DecomposeOptions`` from a request's species and option map; one ``InputError`` naming the option
    for an unknown name or a bad value (``DecomposeOptions`` checks every value), or for ``points``
    below ``min_points``. A whole number sent as a float (2.0) counts as that int."""
    from arboretum_server.decompose.options import WHOLE_LIMITS, DecomposeOptions
    from arboretum_server.decompose.preprocess import check_points

    known = {f.name for f in dataclasses.fields(DecomposeOptions)}
    bad = sorted(set(options) - known)
    if bad:
        raise InputError(f"unknown decomposition option(s): {', '.join(bad)}")
    opts = {k: _int_if_whole(v) if k in WHOLE_LIMITS else v for k, v in options.items()}
    if isinstance(opts.get("sc_bins"), list | tuple):
        opts["sc_bins"] = tuple(_int_if_whole(b) for b in opts["sc_bins"])
    o = DecomposeOptions(**{"species": species.lower(), **opts})
    check_points(o)  # now, not in the worker
    return o


def check_labels(labels: np.ndarray | None, field: str) -> None:
    """``InputError`` naming ``field`` and the values found when ``labels`` hold anything but WOOD 0 and
    LEAF 1 (ASPRS classes 2 and 5, say): the decomposition would take every non-zero label for leaf. The
    words of the CLI's check of a labels column (``pointio_formats.check_labels``)."""
    if labels is None:
        return
    bad = np.setdiff1d(np.unique(labels), [0, 1])
    if bad.size:
        shown = ", ".join(str(int(b)) for b in bad[:5]) + (", ..." if bad.size > 5 else "")
        raise InputError(f"{field}: labels must be 0 (wood) or 1 (leaf); found {shown}")


def _int_if_whole(v: Any) -> Any:
    """``v`` as an int when it is a finite float with no fraction (2.0), else ``v`` as it is."""
    return int(v) if isinstance(v, float) and v.is_integer() else v


def import_job(progress, library_path: str, points: np.ndarray, labels: np.ndarray | None, name: str,
               species: str, options: dict) -> dict:
    """Worker: decompose ``points`` and add one example per main branch to the library."""
    from arboretum_library.model import Provenance
    from arboretum_library.store import Library
    from arboretum_server.decompose.examples import make_examples
    from arboretum_server.decompose.notes import bare_note, notes
    from arboretum_server.decompose.pipeline import decompose

    opts = options_from(species, options)
    prov = Provenance(name, points_sha256(points, labels), opts.species, opts.as_dict())
    with Library.open(library_path) as lib:  # a retried request (a client's timeout) finds its examples there
        if there := _already(lib, prov):
            return there
    dec = decompose(points, opts, progress, labels=labels)
    said = notes(opts, dec.stats)  # before anything is stored
    stem = "".join(c if c.isalnum() or c in "-_" else "-" for c in name)[:60] or "scan"
    with Library.open(library_path) as lib:  # made by import_scan (ctx.library()): a library gone meanwhile stays gone
        with lib.locked():  # checked again: the same request may have been stored while this one decomposed
            if there := _already(lib, prov):
                return there
            examples = lib.add_new(make_examples(dec.hbl, prov), stem)  # ids picked under the lock
    if bare := bare_note(examples, named=True):
        said = [*said, bare]
    return {"ids": [e.id for e in examples], "stats": dec.stats, "notes": said}


def points_sha256(points: np.ndarray, labels: np.ndarray | None) -> str:
    """Hex SHA-256 of a request's points (as little-endian float64) and labels: an import's source digest,
    as a file's bytes are the CLI's, so the same points sent again are known."""
    h = hashlib.sha256(np.ascontiguousarray(points, "<f8").tobytes())
    if labels is not None:
        h.update(np.ascontiguousarray(labels, "|u1").tobytes())
    return h.hexdigest()


def _already(lib, prov) -> dict | None:
    """The reply for points already imported with the same name, species and options (nothing stored), or
    None. Before session 17 every retry stored the examples again."""
    from arboretum_server.decompose.examples import split_runs

    same = [i for i in split_runs(lib, sorted(lib.find_source(prov.source_sha256)), prov)[0]
            if lib.provenance(i).source == prov.source]
    if not same:
        return None
    return {"ids": [], "stats": {}, "notes": [f"already in the library as ids {', '.join(same[:8])}"
                                              f"{', ...' if len(same) > 8 else ''} (these points, imported with "
                                              "the same options): nothing stored"]}


def import_scan(ctx: Context, req: P.LibraryImport) -> Job:
    check_labels(req.labels, "library.import.labels")
    ctx.library()  # fail now, not in the worker, when there is no library
    options_from(req.species, req.options)
    kwargs = {"library_path": str(ctx.library_path), "points": req.points, "labels": req.labels,
              "name": req.name, "species": req.species, "options": req.options}

    def finish(result: dict) -> P.LibraryImported:
        return P.LibraryImported(ids=tuple(result["ids"]), stats=_jsonable(result["stats"]),
                                 notes=tuple(result["notes"]))

    return Job(f"{__name__}:import_job", kwargs, finish)


def _jsonable(d: dict) -> dict:
    """The entries of ``d`` that are numbers, strings, or lists and dicts of them (``trunk_columns``), as
    plain Python values; anything else is left out."""
    out = {}
    for k, v in d.items():
        try:
            out[k] = _plain(v)
        except TypeError:
            continue
    return out


def _plain(v):
    """``v`` as plain numbers, strings, lists and str-keyed dicts; TypeError for anything else."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, str | int | float | bool):
        return v
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    if isinstance(v, dict) and all(isinstance(k, str) for k in v):
        return {k: _plain(x) for k, x in v.items()}
    raise TypeError(type(v).__name__)


HANDLERS = {
    P.LibraryList: list_examples, P.LibrarySearch: search, P.LibraryGet: get, P.LibraryDelete: delete,
    P.LibraryImport: import_scan,
}
