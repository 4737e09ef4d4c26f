"""A request carrying arrays or body fields its type does not declare is answered with a protocol error
(session 28).

They were dropped without a word: a client's misspelt ``label`` array or ``nam`` field ran the request
with the default instead. Header keys stay ignored (the envelope's optional keys, ``wire``), and so do
undeclared fields of replies and events (a client keeps working against a server that adds one).
"""

from __future__ import annotations

import numpy as np
import pytest
import zmq

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly, Placement
from arboretum_library.errors import ProtocolError
from arboretum_library.geometry import make_transform
from arboretum_library.wire import Message, encode


def refused(m: Message) -> str:
    """The message of the ProtocolError parsing ``m`` raises (its code: protocol)."""
    with pytest.raises(ProtocolError) as e:
        P.parse(encode(m))
    assert e.value.code == "protocol"
    return str(e.value)


def test_an_undeclared_array_is_named_with_what_the_type_takes():
    pts = np.zeros((10, 3))
    said = refused(Message("library.import", 1, {"name": "x"}, {"points": pts, "label": np.zeros(10, np.uint8)}))
    assert said == ("library.import: undeclared array(s) 'label' (a misspelt field?); library.import takes body "
                    "fields name, species, options and arrays points, labels")
    assert refused(Message("ping", 2, {}, {"points": pts})) == (
        "ping: undeclared array(s) 'points' (a misspelt field?); ping takes body fields none and arrays none")


def test_an_undeclared_body_field_is_treated_alike():
    assert refused(Message("session.new", 3, {"nam": "x"})) == (
        "session.new: undeclared body field(s) 'nam' (a misspelt field?); session.new takes body fields name and "
        "arrays none")


def test_a_missing_field_and_its_misspelling_are_said_in_one_error():
    said = refused(Message("refine.open", 4, {"session": "s"}, {"point": np.zeros((5, 3))}))
    assert said.startswith("refine.open: missing field(s) points; undeclared array(s) 'point' (a misspelt field?)")


def test_many_undeclared_names_are_listed_up_to_8_and_cut():
    arrays = {f"{'x' * 50}{i}": np.zeros(1) for i in range(12)}
    said = refused(Message("ping", 5, {}, arrays))
    assert said.count("'x") == 8 and ", ... (12 in all)" in said and "x" * 41 not in said


def test_record_arrays_go_with_their_record_field_only():
    a = Assembly((Placement("a", "ex-0", make_transform(t=[0, 0, 0.2])),))
    frames = P.to_frames(P.SessionLoad(assembly=a, name="x"), 6)
    assert len(frames) > 1  # the transform travels as an array frame "assembly/..."
    got = P.parse(frames)[1].assembly  # as every client sends it
    assert np.array_equal(got.placements[0].T_world_example, a.placements[0].T_world_example)
    said = refused(Message("session.load", 7, {"name": "x"}, {"assembly/placements": np.zeros(2)}))
    assert said.startswith("session.load: missing field(s) assembly; undeclared array(s) 'assembly/placements'")


def test_requests_as_clients_build_them_still_parse():
    reqs = [P.Ping(), P.SessionNew(name="n"), P.LibraryImport(points=np.zeros((20, 3)), labels=np.zeros(20, np.uint8)),
            P.InsertLobe(session="s", indices=np.arange(4)), P.RefineOpen(session="s", points=np.zeros((20, 3)))]
    for i, req in enumerate(reqs):
        assert type(P.parse(P.to_frames(req, i))[1]) is type(req)


def test_replies_and_events_keep_ignoring_what_they_do_not_know():
    assert P.parse(encode(Message("pong", 8, {"later": 1}, {"extra": np.zeros(3)})))[1] == P.Pong()
    assert isinstance(P.parse(encode(Message("progress", 9, {"done": 1.0, "new": "x"})))[1], P.Progress)
    assert P.parse(encode(Message("ping", 10, {}, {}, client="abc")))[1] == P.Ping()  # header keys: as before


def test_a_server_answers_the_protocol_error_and_serves_on(served):
    s = zmq.Context.instance().socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.RCVTIMEO, 10_000)
    s.connect(served.endpoint)
    try:
        s.send_multipart(encode(Message("session.new", 41, {"nam": "typo"})))
        rid, reply = P.parse(s.recv_multipart())
        assert rid == 41 and isinstance(reply, P.Error) and reply.code == "protocol"
        assert reply.message.startswith("session.new: undeclared body field(s) 'nam'")
        s.send_multipart(P.to_frames(P.SessionNew(name="typo"), 42))
        rid, reply = P.parse(s.recv_multipart())
        assert rid == 42 and isinstance(reply, P.SessionInfo)
    finally:
        s.close(0)
