"""Refinement service fixes of session 12 (helper-92's hunt): a commit of a tree already in the library
stores nothing, across undo/redo and restarts (by content, not by revision in memory); ``refine.points``
sends float64 (float32 moved UTM points by up to 0.25 m); labels other than 0/1 are refused on the wire."""

from __future__ import annotations

import os

import numpy as np
import pytest

from arboretum_library import protocol as P
from factories import (
    TOY_DRAFT_OPTIONS,
    dispatcher,
    library_ids,
    open_toy_draft,
    reply_of,
    toy_cloud,
)

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


@pytest.fixture
def server(folders):
    with dispatcher(*folders) as d:
        yield d


def repeat_note(reply) -> bool:
    return any(P.ALREADY_COMMITTED in n for n in reply.notes)


# -- 1. a tree already in the library is not stored again -------------------------------------------
def test_undo_and_redo_back_to_committed_trees_store_nothing(server):
    sid = open_toy_draft(server)
    first = reply_of(server, P.RefineCommit(session=sid))
    reply_of(server, P.RemoveLobe(session=sid, lobe=0))
    edited = reply_of(server, P.RefineCommit(session=sid))
    assert not set(first.ids) & set(edited.ids) and len(library_ids(server)) == 6
    reply_of(server, P.RefineUndo(session=sid))
    undone = reply_of(server, P.RefineCommit(session=sid))  # HEAD: stored the first tree again (9 examples)
    assert undone.ids == first.ids and repeat_note(undone)
    reply_of(server, P.RefineRedo(session=sid))
    redone = reply_of(server, P.RefineCommit(session=sid))
    assert redone.ids == edited.ids and repeat_note(redone)
    assert len(library_ids(server)) == 6
    assert undone.notes[-1] == (f"this draft {P.ALREADY_COMMITTED}, unchanged since, as "
                                f"{first.ids[0]}..{first.ids[-1]} (3 examples): not stored again")


def test_a_commit_after_a_restart_stores_nothing(folders):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        first = reply_of(server, P.RefineCommit(session=sid)).ids
    with dispatcher(*folders) as server:  # a new server: the draft is rebuilt from its saved scan
        again = reply_of(server, P.RefineCommit(session=sid))
        assert again.ids == first and repeat_note(again)  # HEAD: 3 more examples
        assert library_ids(server) == sorted(first)


def test_the_same_scan_in_another_session_is_the_same_tree(server):
    first = reply_of(server, P.RefineCommit(session=open_toy_draft(server))).ids
    again = reply_of(server, P.RefineCommit(session=open_toy_draft(server)))
    assert again.ids == first and repeat_note(again) and len(library_ids(server)) == 3


def test_another_name_or_other_points_is_another_tree(server):
    first = reply_of(server, P.RefineCommit(session=open_toy_draft(server))).ids
    renamed = reply_of(server, P.RefineCommit(session=open_toy_draft(server, name="toy2")))
    moved = reply_of(server, P.RefineCommit(session=open_toy_draft(server, shift=(0.0, 0.0, 0.001))))
    assert not repeat_note(renamed) and not repeat_note(moved)
    assert len({*first, *renamed.ids, *moved.ids}) == 9 and len(library_ids(server)) == 9


def test_a_partly_stored_tree_is_stored_whole_with_a_note(server):
    sid = open_toy_draft(server)
    first = reply_of(server, P.RefineCommit(session=sid)).ids
    reply_of(server, P.LibraryDelete(id=first[0]))
    again = reply_of(server, P.RefineCommit(session=sid))
    assert not set(again.ids) & set(first) and len(library_ids(server)) == 5
    assert not repeat_note(again)
    assert (f"2 of 3 examples are the same as {first[1]}, {first[2]} in the library; "
            "stored again with the rest (a commit stores the whole tree)") in again.notes


def test_the_content_hash_holds_no_id():
    import json

    from arboretum_library.folders import encode
    from factories import make_example

    ex = make_example(np.random.default_rng(3), id="a-0001")
    other = make_example(np.random.default_rng(3), id="b-0002")
    (meta_a, npz_a), (meta_b, npz_b) = encode(ex), encode(other, created="2000-01-01T00:00:00Z")
    assert npz_a == npz_b and meta_a != meta_b
    assert json.loads(meta_a)["arrays_sha256"] == json.loads(meta_b)["arrays_sha256"]


# -- 2. refine.points in float64 --------------------------------------------------------------------------
def test_refine_points_keep_utm_coordinates_exactly(server):
    utm = (500_000.0, 5_400_000.0, 300.0)
    sid = open_toy_draft(server, options={**TOY_DRAFT_OPTIONS, "height": None}, shift=utm)
    cloud = reply_of(server, P.RefinePoints(session=sid))
    assert cloud.points.dtype == np.float64
    rid, parsed = P.parse(P.to_frames(cloud, 9))  # what the client decodes
    assert rid == 9 and parsed.points.dtype == np.float64
    assert np.array_equal(parsed.points, cloud.points)
    assert cloud.points[:, 0].min() > 499_990.0  # the scan's own units: the UTM offset is still there
    assert len(np.unique(parsed.points, axis=0)) == len(parsed.points)


def test_refine_points_are_the_drafts_points(server):
    utm = (500_000.0, 5_400_000.0, 300.0)
    pts, labels = toy_cloud()
    sid = reply_of(server, P.SessionNew()).session
    state = reply_of(server, P.RefineOpen(session=sid, points=pts + utm, labels=labels, name="utm",
                                    options={**TOY_DRAFT_OPTIONS, "height": None}))
    got = P.parse(P.to_frames(reply_of(server, P.RefinePoints(session=sid)), 1))[1].points
    assert np.abs(got - state.hbl.points).max() == 0.0  # HEAD (float32): 0.25 m


def test_an_older_client_still_reads_float64_points_as_float32():
    import dataclasses

    from arboretum_library.protocol_base import _check_array

    cloud = P.RefineCloud(points=np.array([[500_000.25, 5_400_000.5, 300.125]]), labels=np.array([1], np.uint8),
                          lobe_of=np.array([-1], np.int32))
    sent = P.parse(P.to_frames(cloud, 1))[1].points
    spec = {**next(f for f in dataclasses.fields(P.RefineCloud) if f.name == "points").metadata, "dtype": "<f4"}
    old = _check_array("refine.cloud.points", spec, sent)
    assert old.dtype == np.float32 and np.allclose(old, sent, atol=0.5)


# -- 3. labels other than 0/1 are refused -----------------------------------------------------------------
def asprs(pts: np.ndarray) -> np.ndarray:
    """ASPRS classes: ground 2 under the 5th percentile of height, high vegetation 5 above."""
    return np.where(pts[:, 2] < np.percentile(pts[:, 2], 5), 2, 5).astype(np.uint8)


@pytest.mark.parametrize("kind", ["refine.open", "library.import"])
def test_labels_other_than_wood_and_leaf_are_refused_before_any_work(server, kind):
    pts, _ = toy_cloud()
    if kind == "refine.open":
        req = P.RefineOpen(session=reply_of(server, P.SessionNew()).session, points=pts, labels=asprs(pts))
    else:
        req = P.LibraryImport(points=pts, labels=asprs(pts))
    reply = server.handle(req)  # not a Job: refused before any decomposition
    assert isinstance(reply, P.Error) and reply.code == "bad_input"
    assert reply.message == f"{kind}.labels: labels must be 0 (wood) or 1 (leaf); found 2, 5"
    assert library_ids(server) == []


def test_many_bad_labels_are_shown_five_at_most(server):
    pts, _ = toy_cloud()
    labels = (np.arange(len(pts)) % 9).astype(np.uint8)
    reply = server.handle(P.LibraryImport(points=pts, labels=labels))
    assert reply.message == "library.import.labels: labels must be 0 (wood) or 1 (leaf); found 2, 3, 4, 5, 6, ..."


def test_wood_and_leaf_labels_still_open(server):
    pts, labels = toy_cloud()
    assert set(np.unique(labels)) == {0, 1}
    sid = reply_of(server, P.SessionNew()).session
    for req in (P.RefineOpen(session=sid, points=pts, labels=labels, options=TOY_DRAFT_OPTIONS),
                P.LibraryImport(points=pts, labels=labels, options=TOY_DRAFT_OPTIONS)):
        assert type(server.handle(req)).__name__ == "Job"  # accepted: the decomposition would run


# -- 4. library.import names examples without lobes, as refine.commit and decompose do ----------------
def test_an_import_names_its_bare_examples(server):
    pts, labels = toy_cloud()
    done = reply_of(server, P.LibraryImport(points=pts, labels=labels, name="toy",
                                      options={"n_main": 12, "n_lobes": 3, "points": 4000}))
    bare = [i for i in done.ids if reply_of(server, P.LibraryGet(id=i)).example.structure.lobes == ()]
    assert 9 <= len(bare) < len(done.ids) == 12
    shown = ", ".join(bare[:4]) + (", ..." if len(bare) > 4 else "")
    assert done.notes[-1] == f"{len(bare)} of 12 examples have no lobes ({shown}): they grow no twigs or leaves"


def test_a_commit_of_no_examples_answers_no_ids(server, monkeypatch):
    """helper-99: with no example made, the look-up's result was never bound (an internal error)."""
    import arboretum_server.decompose.examples as examples

    sid = open_toy_draft(server)
    monkeypatch.setattr(examples, "make_examples", lambda hbl, prov, new_id=None: [])
    done = reply_of(server, P.RefineCommit(session=sid))
    assert done.ids == () and library_ids(server) == []
