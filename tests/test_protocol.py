"""Typed messages: checked when built, identical after a trip over the wire, one generated reference."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import msgpack
import numpy as np
import pytest

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly, Placement
from arboretum_library.errors import ProtocolError
from arboretum_library.wire import PROTOCOL_VERSION, Message, encode
from factories import make_example, make_hbl

DOCS = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"


def sample(cls, rng):
    """A message of ``cls`` with every field set to a plausible non-default value."""
    kwargs = {}
    hints = typing.get_type_hints(cls, vars(P))
    for f in dataclasses.fields(cls):
        if "dtype" in f.metadata:
            shape = tuple(s if s is not None else 5 for s in f.metadata["shape"])
            kwargs[f.name] = (rng.random(shape) * 10).astype(f.metadata["dtype"])
            continue
        tp = hints[f.name]
        if tp is P.HBL:
            kwargs[f.name] = make_hbl(rng, n_points=60)
        elif tp is P.Example:
            kwargs[f.name] = make_example(rng, n_points=50)
        elif tp is P.Assembly:
            kwargs[f.name] = Assembly((Placement("a#1", "ex-1", np.eye(4), 1.5),), (make_example(rng, id="s-1"),))
        elif tp is str:
            kwargs[f.name] = f"{f.name}-x"
        elif tp is bool:
            kwargs[f.name] = True
        elif tp is int:
            kwargs[f.name] = 7
        elif tp is float:
            kwargs[f.name] = 2.5
        elif tp is dict:
            kwargs[f.name] = {"k": 1, "nested": {"x": [1, 2]}}
        elif typing.get_origin(tp) is tuple:
            elem = typing.get_args(tp)[0]
            kwargs[f.name] = ({"id": "a"},) if elem is dict else (1, 2) if elem is int else ("a", "b")
    return cls(**kwargs)


def same(a, b) -> None:
    from arboretum_library.codec import flatten

    ma, aa = flatten(a)
    mb, ab = flatten(b)
    assert ma == mb
    assert sorted(aa) == sorted(ab)
    for k in aa:
        assert aa[k].dtype == ab[k].dtype and np.array_equal(aa[k], ab[k]), k


@pytest.mark.parametrize("name", sorted(P.REGISTRY))
def test_every_message_round_trips_exactly(name, rng):
    msg = sample(P.REGISTRY[name], rng)
    rid, back = P.parse(P.to_frames(msg, 12345))
    assert rid == 12345 and type(back) is type(msg)
    same(msg, back)


def test_requests_name_registered_replies():
    for cls in P.REGISTRY.values():
        if issubclass(cls, P.Request):
            assert cls.REPLY.TYPE in P.REGISTRY and issubclass(cls.REPLY, P.Reply), cls.TYPE
    long = sorted(c.TYPE for c in P.REGISTRY.values() if issubclass(c, P.Request) and c.LONG)
    assert long == ["export.mesh", "export.modules", "grow", "library.import", "refine.open"]


def test_arrays_are_checked_and_normalised_when_built():
    m = P.AddExample(session="s", example_id="e", T_world_example=np.eye(4, dtype=np.float32))
    assert m.T_world_example.dtype == np.float64
    with pytest.raises(ProtocolError, match=r"T_world_example: expected shape \(4, 4\), got \(3, 3\)"):
        P.AddExample(session="s", example_id="e", T_world_example=np.eye(3))
    with pytest.raises(ProtocolError, match="dtype <f8 does not fit <i8"):
        P.InsertLobe(session="s", indices=np.zeros(3))
    with pytest.raises(ProtocolError, match="NaN or infinite"):
        P.LibraryImport(points=np.full((2, 3), np.nan))
    with pytest.raises(ProtocolError, match="array is required"):
        P.LibraryImport(points=None)


def test_scalars_are_checked_when_built():
    with pytest.raises(ProtocolError, match="lobe: expected an integer"):
        P.RemoveLobe(session="s", lobe="3")
    with pytest.raises(ProtocolError, match="expected an integer, got bool"):
        P.RemoveLobe(session="s", lobe=True)
    with pytest.raises(ProtocolError, match="session: expected a string"):
        P.SessionGet(session=5)
    with pytest.raises(ProtocolError, match="must be finite"):
        P.TransformExample(session="s", instance="i", T_world_example=np.eye(4), scale=float("inf"))
    assert P.MergeLobes(session="s", lobes=[1, 2]).lobes == (1, 2)


def frames_of(type_name, body, arrays=None):
    return encode(Message(type_name, 3, body, arrays or {}))


@pytest.mark.parametrize(
    "frames, match",
    [
        (lambda: frames_of("no.such.op", {}), "unknown message type 'no.such.op'"),
        (lambda: frames_of("session.get", {}), "missing field"),
        (lambda: frames_of("session.get", {"session": [1]}), "expected a string"),
        (lambda: frames_of("refine.insert_lobe", {"session": "s"}, {"indices": np.zeros((2, 2), np.int64)}), "expected shape"),
        (lambda: frames_of("library.get", {"id": "x"}) + [b"\x00"], "header lists 0 arrays"),
        (lambda: [msgpack.packb({"v": PROTOCOL_VERSION + 1, "id": 1, "type": "ping"})], "version"),
        (lambda: frames_of("session.load", {"assembly": {"placements": [{"instance": 3}]}}), "not a valid Assembly"),
    ],
)
def test_malformed_messages_raise_one_protocol_error(frames, match):
    with pytest.raises(ProtocolError, match=match):
        P.parse(frames())


def test_unknown_types_have_their_own_code():
    with pytest.raises(P.UnknownType) as e:
        P.parse(frames_of("nope", {}))
    assert e.value.code == "unknown_type"


def test_strokes_pack_and_unpack():
    strokes = [np.zeros((3, 3)), np.ones((5, 3))]
    pts, sizes = P.pack_strokes(strokes)
    assert pts.shape == (8, 3) and sizes.tolist() == [3, 5]
    back = P.unpack_strokes(pts, sizes)
    assert [len(s) for s in back] == [3, 5] and np.array_equal(back[1], strokes[1])
    with pytest.raises(ProtocolError, match="add up to 7"):
        P.unpack_strokes(pts, np.array([3, 4]))


def test_docs_protocol_md_is_current():
    assert DOCS.read_text() == P.describe(), "regenerate: python -m arboretum_library.protocol > docs/protocol.md"


def test_reference_lists_every_message_with_its_fields():
    text = P.describe()
    for name, cls in P.REGISTRY.items():
        assert f"## `{name}`" in text
        for f in dataclasses.fields(cls):
            assert f"| `{f.name}` |" in text
