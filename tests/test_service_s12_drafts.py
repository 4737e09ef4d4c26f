"""Saved refinement drafts after an upgrade (helper-96's review): a draft records the decomposition version
it was made with and is not replayed by a server of another one (each request says so; its files are
kept); a replay failing at an edit keeps the edits before it and names the one that failed; a torn
journal tail is dropped so later edits are read back."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields, replace

import numpy as np
import pytest

from arboretum_library import protocol as P
from arboretum_library.codec import load_record, save_record
from arboretum_library.errors import InputError
from arboretum_server.service import refine_store
from arboretum_server.service.refine_store import DECOMPOSE_VERSION, RefineSource
from factories import (
    TOY_DRAFT_OPTIONS,
    dispatcher,
    open_toy_draft,
    reply_of,
    toy_cloud,
)

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def refine_files(folders, sid: str) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((folders[0] / "sessions").glob(f"{sid}.refine.*"))}


def error_of(server, req) -> P.Error:
    reply = server.run(req)
    assert isinstance(reply, P.Error), reply
    return reply


@dataclass(frozen=True, eq=False)
class OldSource:
    """``RefineSource`` as session 11 wrote it: no ``version``."""

    points: np.ndarray
    labels: np.ndarray
    name: str = "scan"
    species: str = "unknown"
    options: dict = field(default_factory=dict)
    generation: str = ""


OldSource.__name__ = "RefineSource"  # the record kind the file names


def save_as_version(path, version: int) -> None:
    src = load_record(path, RefineSource)
    if version == 1:  # written before versions were recorded: no field at all
        save_record(path, OldSource(**{f.name: getattr(src, f.name) for f in fields(OldSource)}))
    else:
        save_record(path, replace(src, version=version))


# -- 1. a draft of another decomposition version -------------------------------------------------------
def test_a_new_draft_records_the_running_version(folders):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
    assert DECOMPOSE_VERSION == 2
    assert load_record(folders[0] / "sessions" / f"{sid}.refine.npz", RefineSource).version == 2


@pytest.mark.parametrize("version, made", [(1, "an older"), (3, "a newer")])
def test_a_draft_of_another_version_is_not_replayed_and_its_files_are_kept(folders, version, made):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        reply_of(server, P.RemoveLobe(session=sid, lobe=0))
    save_as_version(folders[0] / "sessions" / f"{sid}.refine.npz", version)
    before = refine_files(folders, sid)
    assert sorted(before) == [f"{sid}.refine.journal", f"{sid}.refine.npz"]
    said = (f"the refinement draft of session {sid} was made by {made} Arboretum (decomposition version "
            f"{version}; this server's is 2), which decomposes and splits differently, so it cannot be rebuilt "
            f"exactly; its files ({sid}.refine.npz, {sid}.refine.journal) are kept; refine.open of the scan "
            "again starts over")
    with dispatcher(*folders) as server:  # HEAD: replayed the edit on today's tree and answered
        for req in (P.RefinePoints(session=sid), P.RemoveLobe(session=sid, lobe=0), P.RefineUndo(session=sid),
                    P.RefineCommit(session=sid), P.RefinePoints(session=sid)):
            err = error_of(server, req)
            assert (err.code, err.message) == ("bad_input", said)
        assert reply_of(server, P.LibraryList()).entries == ()
        assert refine_files(folders, sid) == before  # nothing rewritten, nothing deleted
        pts, labels = toy_cloud()
        state = reply_of(server, P.RefineOpen(session=sid, points=pts, labels=labels, name="toy", options=TOY_DRAFT_OPTIONS))
        assert state.revision == 0 and not state.can_undo  # started over
        assert reply_of(server, P.RemoveLobe(session=sid, lobe=0)).revision == 1
    assert load_record(folders[0] / "sessions" / f"{sid}.refine.npz", RefineSource).version == 2


# -- 2. a replay that fails at an edit -----------------------------------------------------------------
def repeated_strokes(cloud: P.RefineCloud, lobe: int) -> dict:
    """Two strokes over the same three points of ``lobe``: accepted before session 12, refused now."""
    stroke = cloud.points[cloud.lobe_of == lobe][:3]
    sp, sz = P.pack_strokes([stroke, stroke])
    return {"stroke_points": sp, "stroke_sizes": sz}


def test_a_replay_failing_at_an_edit_keeps_the_edits_before_it(folders):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        reply_of(server, P.RemoveLobe(session=sid, lobe=0))
        kept = reply_of(server, P.RefinePoints(session=sid))
        arrays = repeated_strokes(kept, 0)
        refused = error_of(server, P.SplitLobe(session=sid, lobe=0, seed=0, **arrays)).message
    folder = folders[0] / "sessions"
    gen = load_record(folder / f"{sid}.refine.npz", RefineSource).generation
    refine_store.append(folder, sid, gen, "split_lobe", {"lobe": 0, "seed": 0}, arrays)  # an older server's
    refine_store.append(folder, sid, gen, "undo", {})
    journal = (folder / f"{sid}.refine.journal").read_bytes()
    with dispatcher(*folders) as server:  # HEAD: every request failed with the split's error
        err = error_of(server, P.RefinePoints(session=sid))
        assert err.code == "bad_input"
        assert err.message == (f"the saved refinement draft could not be rebuilt past edit 2 of 3 (split_lobe: "
                               f"{refused}); it was kept as it was before that edit (1 edit replayed, 2 dropped); "
                               "this request was not run: send it again if it still applies")
        now = reply_of(server, P.RefinePoints(session=sid))
        assert np.array_equal(now.lobe_of, kept.lobe_of) and np.array_equal(now.points, kept.points)
        assert reply_of(server, P.MergeLobes(session=sid, lobes=(0, 1))).revision == 2
        merged = reply_of(server, P.RefinePoints(session=sid))
    assert (folder / f"{sid}.refine.journal").read_bytes().startswith(journal)  # the old entries are kept
    with dispatcher(*folders) as server:  # rebuilt again, without error: the kept edit and the new one
        again = reply_of(server, P.RefinePoints(session=sid))
        assert np.array_equal(again.lobe_of, merged.lobe_of)
        undone = reply_of(server, P.RefineUndo(session=sid))
        assert undone.revision == 3 and undone.can_undo  # two edits replayed
        assert np.array_equal(reply_of(server, P.RefinePoints(session=sid)).lobe_of, kept.lobe_of)


def test_decompose_job_reports_the_edit_it_stopped_at():
    from arboretum_server.service.handlers.refine import decompose_job

    pts, labels = toy_cloud()
    edits = ({"kind": "remove_lobe", "args": {"lobe": 0}}, {"kind": "merge_lobes", "args": {"lobes": [0, 99]}},
             {"kind": "undo", "args": {}})
    r = decompose_job(lambda *a: None, pts, labels, "unknown", TOY_DRAFT_OPTIONS, edits)
    assert (len(r["states"]), r["index"], r["revision"]) == (2, 1, 1)
    assert r["failed"]["done"] == 1 and r["failed"]["kind"] == "merge_lobes" and "99" in r["failed"]["error"]


# -- 3. a torn journal tail ---------------------------------------------------------------------------
def test_edits_after_a_torn_journal_tail_are_read_back(folders):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        reply_of(server, P.RemoveLobe(session=sid, lobe=0))
    with open(folders[0] / "sessions" / f"{sid}.refine.journal", "ab") as fh:
        fh.write(b"\x40\x00\x00")  # a kill during an append
    with dispatcher(*folders) as server:
        assert reply_of(server, P.RemoveLobe(session=sid, lobe=0)).revision == 2
        two = reply_of(server, P.RefinePoints(session=sid))
    with dispatcher(*folders) as server:  # HEAD: the second edit was behind the torn bytes, unread
        assert np.array_equal(reply_of(server, P.RefinePoints(session=sid)).lobe_of, two.lobe_of)
        assert reply_of(server, P.RefineUndo(session=sid)).revision == 3


def test_a_passing_failure_during_a_replay_keeps_the_whole_journal(folders, monkeypatch):
    """helper-99: a MemoryError at edit 2 of 3 was taken as the edit's refusal, and edits 2 and 3 were
    dropped for good. Only an edit's own refusal (ArboretumError) shortens the draft; anything else fails
    the request and leaves the files alone."""
    import arboretum_server.service.handlers.refine as handlers

    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        for _ in range(3):
            last = reply_of(server, P.RemoveLobe(session=sid, lobe=0))
    assert last.revision == 3
    journal = (folders[0] / "sessions" / f"{sid}.refine.journal").read_bytes()
    real, calls = handlers.apply_edit, []

    def flaky(dec, kind, args):
        calls.append(kind)
        if len(calls) == 2:
            raise MemoryError()
        return real(dec, kind, args)

    monkeypatch.setattr(handlers, "apply_edit", flaky)
    with dispatcher(*folders) as server:
        assert error_of(server, P.RefinePoints(session=sid)).code == "internal"
    assert (folders[0] / "sessions" / f"{sid}.refine.journal").read_bytes() == journal
    monkeypatch.setattr(handlers, "apply_edit", real)
    with dispatcher(*folders) as server:  # memory back: all three edits
        assert reply_of(server, P.RefineUndo(session=sid)).revision == 4


def test_requests_waiting_on_a_failed_rebuild_are_all_refused(folders):
    """helper-99: two requests arriving while the draft is rebuilt each start a rebuild; the first to
    finish shortened the draft and refused, the second ran on the shorter draft it was not meant for."""
    from arboretum_server.service.jobs import call_target

    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        reply_of(server, P.RemoveLobe(session=sid, lobe=0))
    folder = folders[0] / "sessions"
    gen = load_record(folder / f"{sid}.refine.npz", RefineSource).generation
    refine_store.append(folder, sid, gen, "merge_lobes", {"lobes": [0, 99]})  # refused on replay
    with dispatcher(*folders) as server:
        jobs = [server.handle(P.RefinePoints(session=sid)), server.handle(P.RemoveLobe(session=sid, lobe=0))]
        results = [call_target(j.target, j.kwargs, lambda *a: None) for j in jobs]
        for j, r in zip(jobs, results):
            with pytest.raises(InputError, match="could not be rebuilt past edit 2 of 2"):
                j.finish(r)
        undone = reply_of(server, P.RefineUndo(session=sid))
        assert (undone.revision, undone.can_undo) == (2, False)  # one edit kept (revision 1), none run since
