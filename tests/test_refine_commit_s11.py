"""``refine.commit`` twice on an unchanged draft stores it once (a double press of C in the client), and
examples left without lobes are named in a note (helper-82's hunt, findings 6)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from arboretum_library import protocol as P
from factories import dispatcher, library_ids, open_toy_draft, reply_of, service_folders

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


@pytest.fixture
def server(tmp_path):
    with dispatcher(*service_folders(tmp_path)) as d:
        yield d


ok = reply_of


@pytest.fixture
def draft(server):
    return open_toy_draft(server)


def test_a_second_commit_of_the_same_draft_answers_the_first_ids(server, draft):
    first = ok(server, P.RefineCommit(session=draft))
    assert len(first.ids) == 3 and library_ids(server) == sorted(first.ids)
    again = ok(server, P.RefineCommit(session=draft))
    assert again.ids == first.ids and library_ids(server) == sorted(first.ids)  # 3 examples, not 6
    assert again.notes[-1] == (f"this draft was committed already, unchanged since, as {first.ids[0]}..{first.ids[-1]} "
                               "(3 examples): not stored again")


def test_an_edit_or_a_deleted_example_commits_anew(server, draft):
    first = ok(server, P.RefineCommit(session=draft)).ids
    ok(server, P.RemoveLobe(session=draft, lobe=0))
    second = ok(server, P.RefineCommit(session=draft)).ids
    assert not set(first) & set(second) and len(library_ids(server)) == 6
    ok(server, P.LibraryDelete(id=second[0]))
    third = ok(server, P.RefineCommit(session=draft))
    assert not set(third.ids) & set(second) and len(library_ids(server)) == 8
    assert not any("committed already" in n for n in third.notes)


def test_an_undo_back_to_a_committed_state_is_that_state(server, draft):
    first = ok(server, P.RefineCommit(session=draft)).ids
    ok(server, P.RemoveLobe(session=draft, lobe=0))
    ok(server, P.RefineUndo(session=draft))
    assert ok(server, P.RefineCommit(session=draft)).ids == first and len(library_ids(server)) == 3


def test_examples_without_lobes_are_named(server, draft):
    for _ in range(5):
        ok(server, P.RemoveLobe(session=draft, lobe=0))
    done = ok(server, P.RefineCommit(session=draft))
    assert len(done.ids) == 3
    assert done.notes[-1] == (f"3 of 3 examples have no lobes ({', '.join(done.ids)}): "
                              "they grow no twigs or leaves")
    assert np.all([ok(server, P.LibraryGet(id=i)).example.structure.lobes == () for i in done.ids])


def test_the_client_status_line_says_a_repeat_stored_nothing():
    from arboretum_client.tools.actions import committed

    assert committed(["toy-0001", "toy-0002"], ()) == "stored toy-0001, toy-0002"
    note = "this draft was committed already, unchanged since, as toy-0001..toy-0002 (2 examples): not stored again"
    assert committed(["toy-0001", "toy-0002"], ("3 lobes asked, 2 found", note)) == f"{note}; 3 lobes asked, 2 found"
    assert committed(["a"], ("1 of 1 examples have no lobes: they grow no twigs or leaves",)) == (
        "stored a; 1 of 1 examples have no lobes: they grow no twigs or leaves")


def test_ids_given_to_another_tree_since_are_no_repeat(server, draft):
    # helper-88: after the committed examples were deleted, the next writer of that name got the same ids;
    # a second press then stored nothing and answered the other tree's ids
    first = ok(server, P.RefineCommit(session=draft)).ids
    for i in first:
        ok(server, P.LibraryDelete(id=i))
    other = ok(server, P.SessionNew()).session
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts, labels = toy_scan(toy_truth(), n=4000, seed=7)
    ok(server, P.RefineOpen(session=other, points=pts, labels=labels, name="toy",
                            options={"n_main": 3, "n_lobes": 4, "points": 4000}))
    assert ok(server, P.RefineCommit(session=other)).ids == first  # the freed ids, another tree
    again = ok(server, P.RefineCommit(session=draft))
    assert not set(again.ids) & set(first) and len(library_ids(server)) == 6
    assert not any("committed already" in n for n in again.notes)
