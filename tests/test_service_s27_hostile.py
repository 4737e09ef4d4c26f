"""Refinement requests a buggy client may send (session 27, helper-189: 88 hostile frames and requests against
a running server, each answered with one Error and the server serving on). A refused edit names its input,
changes nothing and journals nothing: the draft after a restart is the draft before the refusals."""

from __future__ import annotations

import os

import numpy as np
import pytest

from arboretum_library import protocol as P
from factories import dispatcher, open_toy_draft, reply_of

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


@pytest.fixture
def server(folders):
    with dispatcher(*folders) as d:
        yield d


def refused(server, req) -> str:
    reply = server.run(req)
    assert isinstance(reply, P.Error) and reply.code == "bad_input", reply
    return reply.message


def test_an_index_out_of_range_is_named_and_nothing_is_kept(folders):
    with dispatcher(*folders) as server:
        sid = open_toy_draft(server)
        n = len(reply_of(server, P.RefinePoints(session=sid)).points)
        before = reply_of(server, P.RemoveLobe(session=sid, lobe=0)).revision
        msg = refused(server, P.InsertLobe(session=sid, indices=np.array([0, 1, 2, n, n + 1, -3])))
        assert msg == f"insert lobe: point indices must lie in 0..{n - 1}; {n} does not (3 of the 6 selected are out of range)"  # HEAD: no index
        assert refused(server, P.InsertLobe(session=sid, indices=np.zeros(0, np.int64))).startswith(
            "insert lobe: the selection is empty")
        assert refused(server, P.MergeLobes(session=sid, lobes=(0, 99))) == "lobe 99 does not exist (the tree has 4 lobes)"
        state = reply_of(server, P.RefineUndo(session=sid))
        assert state.revision == before + 1 and not state.can_undo  # the refusals made no revision
    with dispatcher(*folders) as server:  # a restart replays the journal: only the remove was kept
        cloud = reply_of(server, P.RefinePoints(session=sid))
        assert cloud.lobe_of.max() == 4  # the undo's draft: all 5 lobes
        state = reply_of(server, P.RefineRedo(session=sid))
        assert len(set(reply_of(server, P.RefinePoints(session=sid)).lobe_of.tolist()) - {-1}) == 4
        assert not state.can_redo


def test_a_tree_with_every_lobe_removed_says_so(server):
    sid = open_toy_draft(server)
    for _ in range(5):
        reply_of(server, P.RemoveLobe(session=sid, lobe=0))
    assert refused(server, P.RemoveLobe(session=sid, lobe=0)) == "lobe 0 does not exist (the tree has no lobes left)"
    assert reply_of(server, P.RefineUndo(session=sid)).can_undo
