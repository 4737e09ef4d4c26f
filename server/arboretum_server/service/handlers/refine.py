"""Refinement of a decomposed scan (VRTree 3.4, Fig. 5): open (a job), point cloud, remove / insert /
merge / split lobe, undo, redo, commit to the library. The operations are ``decompose.refine``'s.

Every edit is journaled (``refine_store``) before the reply; after a restart the first refinement
request of a session rebuilds its draft in a worker (decompose again, replay the edits) and then runs.
A draft made by a server of another ``refine_store.DECOMPOSE_VERSION`` is not rebuilt (each request says
so; its files are kept); a replay that fails at an edit keeps the draft as it was before that edit.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import ArboretumError, InputError
from arboretum_server.service import refine_store
from arboretum_server.service.context import Context
from arboretum_server.service.handlers.assembly import checked_strokes
from arboretum_server.service.handlers.library import check_labels, options_from
from arboretum_server.service.jobs import Job
from arboretum_server.service.sessions import RefineDraft, Session

EDITS = ("remove_lobe", "insert_lobe", "merge_lobes", "split_lobe")
WARM = ("arboretum_server.decompose.refine", "arboretum_server.decompose.clusters", "arboretum_server.decompose.examples",
        "arboretum_server.decompose.tetloops", "arboretum_server.decompose.merge",
        "arboretum_server.decompose.similarity", "arboretum_server.decompose.hullpack",
        "arboretum_server.decompose.graph", "arboretum_server.decompose.grid", "arboretum_server.decompose.lobes",
        "arboretum_server.decompose.smooth")
MAX_SPLIT_STROKES = 100
"""Strokes of one split (one new lobe each; k-means with that many centres runs in the server's loop)."""


def apply_edit(dec: Any, kind: str, args: dict) -> Any:
    """The decomposition after refinement edit ``kind`` with ``args``."""
    from arboretum_server.decompose import refine

    if kind == "remove_lobe":
        return refine.remove_lobe(dec, int(args["lobe"]))
    if kind == "insert_lobe":
        return refine.insert_lobe(dec, args["indices"])
    if kind == "merge_lobes":
        return refine.merge_lobes(dec, [int(j) for j in args["lobes"]])
    strokes = P.unpack_strokes(args["stroke_points"], args["stroke_sizes"])
    return refine.split_lobe(dec, int(args["lobe"]), strokes, int(args["seed"]))


def decompose_job(progress, points: np.ndarray, labels: np.ndarray | None, species: str, options: dict,
                  edits: tuple = ()) -> dict:
    """Worker: decompose ``points`` and replay ``edits``; the draft's states, index and revision, and
    ``failed``: None, or the edit the replay stopped at (``done`` edits before it were replayed)."""
    from arboretum_server.decompose.pipeline import decompose

    lab = labels if labels is not None and len(labels) else None
    draft = RefineDraft([decompose(points, options_from(species, options), progress, labels=lab)])
    failed = None
    for done, e in enumerate(edits):
        try:
            _replay(draft, e)
        except ArboretumError as exc:  # the edit refused now (another rule): keep the edits before it
            failed = {"done": done, "kind": e["kind"], "error": str(exc)}
            break  # any other failure (memory, a bug) fails this request only: the journal stays whole
    return {"states": draft.states, "index": draft.index, "revision": draft.revision, "failed": failed}


def _replay(draft: RefineDraft, e: dict) -> None:
    if e["kind"] in ("undo", "redo"):
        draft.move(-1 if e["kind"] == "undo" else 1)
    else:
        draft.push(apply_edit(draft.current, e["kind"], e["args"]))


def _state(d: RefineDraft) -> P.RefineState:
    return P.RefineState(hbl=d.current.hbl, revision=d.revision, can_undo=d.index > 0,
                         can_redo=d.index < len(d.states) - 1)


def _with_draft(ctx: Context, session_id: str, then: Callable[[Session, RefineDraft], P.Reply]) -> P.Reply | Job:
    """``then(session, draft)``, first rebuilding a saved draft in a worker if the server restarted."""
    s = ctx.sessions.get(session_id)
    if s.refine is not None:
        return then(s, s.refine)
    saved = refine_store.load(ctx.sessions.dir(), s.id)
    if saved is None:
        raise InputError("this session has no scan to refine: send refine.open first")
    src, edits = saved

    def finish(r: dict) -> P.Reply:
        ctx.sessions.still_open(s)
        failed = r.get("failed")
        if s.refine is None:  # else another request rebuilt it meanwhile: keep that one
            kept = src
            if failed:
                kept = refine_store.keep_first(ctx.sessions.dir(), s.id, src, failed["done"], ctx.sessions.fsync)
            s.refine = RefineDraft(r["states"], r["index"], src.name, src.species, r["revision"], kept.generation)
        if failed:  # meant for the whole draft, whichever request rebuilt it: not run on the shorter one
            raise InputError(_replay_failed(failed, len(edits)))
        return then(s, s.refine)

    kwargs = {"points": src.points, "labels": src.labels, "species": src.species, "options": src.options,
              "edits": tuple(edits)}
    return Job(f"{__name__}:decompose_job", kwargs, finish)


def _replay_failed(failed: dict, total: int) -> str:
    n = failed["done"]
    return (f"the saved refinement draft could not be rebuilt past edit {n + 1} of {total} ({failed['kind']}: "
            f"{failed['error']}); it was kept as it was before that edit ({n} edit{'s' * (n != 1)} replayed, "
            f"{total - n} dropped); this request was not run: send it again if it still applies")


def open_scan(ctx: Context, req: P.RefineOpen) -> Job:
    check_labels(req.labels, "refine.open.labels")
    s = ctx.sessions.get(req.session)
    options_from(req.species, req.options)

    def finish(r: dict) -> P.RefineState:
        ctx.sessions.still_open(s)  # closed while the job ran: write nothing
        src = refine_store.start(ctx.sessions.dir(), s.id, req.points, req.labels, req.name, req.species,
                                 req.options, ctx.sessions.fsync)
        s.refine = RefineDraft(r["states"], 0, req.name, req.species, 0, src.generation)
        return _state(s.refine)

    kwargs = {"points": req.points, "labels": req.labels, "species": req.species, "options": req.options}
    return Job(f"{__name__}:decompose_job", kwargs, finish)


def points(ctx: Context, req: P.RefinePoints) -> P.Reply | Job:
    def then(s: Session, d: RefineDraft) -> P.RefineCloud:
        dec = d.current
        return P.RefineCloud(points=dec.hbl.points, labels=dec.labels, lobe_of=dec.lobe_of)

    return _with_draft(ctx, req.session, then)


def _edit(ctx: Context, session_id: str, kind: str, args: dict, arrays: dict | None = None) -> P.Reply | Job:
    def then(s: Session, d: RefineDraft) -> P.RefineState:
        if kind in ("undo", "redo"):
            d.move(-1 if kind == "undo" else 1)
        else:
            d.push(apply_edit(d.current, kind, {**args, **(arrays or {})}))
        refine_store.append(ctx.sessions.dir(), s.id, d.generation, kind, args, arrays, ctx.sessions.fsync)
        return _state(d)

    return _with_draft(ctx, session_id, then)


def remove_lobe(ctx: Context, req: P.RemoveLobe):
    return _edit(ctx, req.session, "remove_lobe", {"lobe": req.lobe})


def insert_lobe(ctx: Context, req: P.InsertLobe):
    return _edit(ctx, req.session, "insert_lobe", {}, {"indices": req.indices})


def merge_lobes(ctx: Context, req: P.MergeLobes):
    return _edit(ctx, req.session, "merge_lobes", {"lobes": list(req.lobes)})


def split_lobe(ctx: Context, req: P.SplitLobe):
    checked_strokes(req.stroke_points, req.stroke_sizes, "split lobe", MAX_SPLIT_STROKES)
    return _edit(ctx, req.session, "split_lobe", {"lobe": req.lobe, "seed": req.seed},
                 {"stroke_points": req.stroke_points, "stroke_sizes": req.stroke_sizes})


def undo(ctx: Context, req: P.RefineUndo):
    return _edit(ctx, req.session, "undo", {})


def redo(ctx: Context, req: P.RefineRedo):
    return _edit(ctx, req.session, "redo", {})


def commit(ctx: Context, req: P.RefineCommit):
    from arboretum_library.model import Provenance
    from arboretum_server.decompose.examples import make_examples
    from arboretum_server.decompose.notes import bare_note, option_notes, scan_notes

    def then(s: Session, d: RefineDraft) -> P.LibraryImported:
        dec = d.current
        said = tuple(option_notes(dec.options) + scan_notes(dec.stats))  # the user chose the lobe count
        lib = ctx.library()
        stats = {"lobes": len(dec.lobes)}
        prov = Provenance(d.name, "", dec.options.species, dec.options.as_dict())
        made = make_examples(dec.hbl, prov)
        hashes = content_hashes(made)
        found: list[str | None] = []
        if made and all(found := _copies(lib, hashes, prov)):  # no lock to answer a repeated commit
            return _committed_already(found, said, stats)
        stem = "".join(c if c.isalnum() or c in "-_" else "-" for c in d.name)[:60] or "scan"
        with lib.locked():  # looked up again with the add: no other writer stores the tree in between
            if made and all(found := _copies(lib, hashes, prov)):
                return _committed_already(found, said, stats)
            examples = lib.add_new(made, stem)  # ids picked under the lock
        same = [i for i in found if i]
        if same:
            said += (f"{len(same)} of {len(made)} examples are the same as {', '.join(same)} in the library; "
                     "stored again with the rest (a commit stores the whole tree)",)
        if bare := bare_note(examples, named=True):
            said += (bare,)
        return P.LibraryImported(ids=tuple(e.id for e in examples), stats=stats, notes=said)

    return _with_draft(ctx, req.session, then)


def _committed_already(found: list, said: tuple, stats: dict) -> P.LibraryImported:
    ids = tuple(i for i in found if i)
    return P.LibraryImported(ids=ids, stats=stats, notes=said + (
        f"this draft {P.ALREADY_COMMITTED}, unchanged since, as {_span(ids)}: not stored again",))


def content_hashes(made: list) -> list[str]:
    """The ``content_sha256`` each example of ``made`` will have in the library."""
    from arboretum_library.folders import encode

    return [json.loads(encode(ex)[0])["arrays_sha256"] for ex in made]


def _copies(lib: Any, hashes: list[str], prov: Any) -> list[str | None]:
    """For each of ``hashes``, the id of an example in ``lib`` with those arrays, or None. Identical: the
    same arrays (the catalog's ``content_sha256``, the SHA-256 of arrays.npz, which holds no id, time or
    provenance: the same tree hashes alike under any id and after a restart) and the same source name
    and species; the lowest such id (an earlier server stored copies)."""
    by_hash = lib.find_content(hashes, prov.source, prov.species)  # one query on the species' rows
    return [by_hash.get(h) for h in hashes]


def _span(ids: tuple[str, ...]) -> str:
    """``ids`` as 'a..b (N examples)', or the one id."""
    return ids[0] if len(ids) == 1 else f"{ids[0]}..{ids[-1]} ({len(ids)} examples)"


HANDLERS = {
    P.RefineOpen: open_scan, P.RefinePoints: points, P.RemoveLobe: remove_lobe, P.InsertLobe: insert_lobe,
    P.MergeLobes: merge_lobes, P.SplitLobe: split_lobe, P.RefineUndo: undo, P.RefineRedo: redo,
    P.RefineCommit: commit,
}
