"""Merge links form a forest wherever an Assembly is built: the model, files on disk, session.load over
the socket, the session store and every edit (no instance merged into two placements, no cycle)."""

from __future__ import annotations

import json
import logging
import time

import msgpack
import numpy as np
import pytest
import zmq
from hypothesis import given, settings
from hypothesis import strategies as st

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly, MergeLink, Placement
from arboretum_library.cli import main
from arboretum_library.codec import META_KEY, arrays_to_npz, load_record, npz_to_arrays, save_record
from arboretum_library.errors import InputError, ValidationError
from arboretum_library.geometry import make_transform
from arboretum_server.assembly.state import Autosave, append_entry
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher
from arboretum_server.service.sessions import Sessions
from arboretum_server.service.socket import Server
from factories import make_library

NAMES = ("a", "b", "c", "d", "e", "f")
ALL = tuple(Placement(n, "ex-0", make_transform(t=[0, 0, 0.1 * i])) for i, n in enumerate(NAMES))


def links(*pairs: str) -> tuple[MergeLink, ...]:
    """``links("ab", "bc")``: b merged into a, c merged into b."""
    return tuple(MergeLink(p[0], p[1], 1, 1) for p in pairs)


def reference(pairs: list[tuple[str, str]]) -> str:
    """'ok', 'two' or 'cycle', the slow way: walk up from every instance at most len(pairs) steps."""
    parent: dict[str, str] = {}
    for a, b in pairs:
        if b in parent:
            return "two"
        parent[b] = a
    for start in parent:
        name = start
        for _ in range(len(pairs) + 1):
            name = parent.get(name, "")
        if name:
            return "cycle"
    return "ok"


# -- the model -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("pairs, match", [
    (("ab", "cb"), r"Assembly\.merges: 'b' is merged into two placements \('a' and 'c'\)"),
    (("ab", "ba"), r"Assembly\.merges: the links through '.' form a cycle"),
    (("ab", "bc", "ca"), r"cycle \('b' -> 'a' -> 'c' -> 'b': each merged into the next\)"),
    (("af", "ab", "bc", "ca"), r"Assembly\.merges: the links through 'a' form a cycle \('a' -> 'c' -> 'b' -> 'a'"),
])
def test_double_merges_and_cycles_are_refused_naming_the_field(pairs, match):
    with pytest.raises(ValidationError, match=match):
        Assembly(ALL, (), links(*pairs))


def test_forests_are_accepted():
    a = Assembly(ALL, (), links("ab", "bc", "cd", "ae", "ef"))  # a chain and a branch, one root
    assert [(m.a, m.b) for m in a.merges] == [("a", "b"), ("b", "c"), ("c", "d"), ("a", "e"), ("e", "f")]
    assert len(Assembly(ALL, (), links("ba", "dc", "fe")).merges) == 3  # three roots
    with pytest.raises(ValidationError, match="must join two placed instances"):
        Assembly(ALL, (), links("aa"))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(NAMES), st.sampled_from(NAMES)).filter(lambda t: t[0] != t[1]),
                max_size=8))
def test_the_check_agrees_with_a_slow_reference(pairs):
    want = reference(pairs)
    try:
        Assembly(ALL, (), tuple(MergeLink(a, b, 0, 0) for a, b in pairs))
        got = "ok"
    except ValidationError as exc:
        got = "two" if "merged into two" in str(exc) else "cycle" if "form a cycle" in str(exc) else str(exc)
    assert got == want


def test_the_check_is_linear_in_the_links():
    n = 40_000
    placements = [Placement(f"p{i}", "ex", np.eye(4)) for i in range(n)]
    chain = tuple(MergeLink(f"p{i}", f"p{i + 1}", 0, 0) for i in reversed(range(n - 1)))  # deepest first
    t0 = time.perf_counter()
    a = Assembly(placements, (), chain)
    took = time.perf_counter() - t0
    assert len(a.merges) == n - 1
    assert took < 2.0, took  # a quadratic walk would visit 8e8 links here
    with pytest.raises(ValidationError, match="cycle"):
        Assembly(placements, (), (*chain, MergeLink(f"p{n - 1}", "p0", 0, 0)))


# -- files on disk -------------------------------------------------------------------------------------
def rewrite_meta(path, edit) -> None:
    """Change the JSON metadata of a record file, as an older Arboretum (or a hand edit) could have left it."""
    arrays = npz_to_arrays(path.read_bytes())
    head = json.loads(arrays.pop(META_KEY).tobytes().decode())
    edit(head["record"])
    arrays[META_KEY] = np.frombuffer(json.dumps(head).encode(), np.uint8)
    path.write_bytes(arrays_to_npz(arrays))


LOOP = [{"a": "b", "b": "a", "vertex_a": 1, "vertex_b": 1}]


def test_a_cyclic_session_file_is_one_clear_input_error(tmp_path, capsys):
    path = save_record(tmp_path / "s.npz", Assembly(ALL[:2], (), links("ab")))
    rewrite_meta(path, lambda r: r["merges"].extend(LOOP))
    with pytest.raises(InputError, match=r"s\.npz: Assembly\.merges: the links through '.' form a cycle"):
        load_record(path, Assembly)
    script = tmp_path / "ops.json"
    script.write_text("[]")
    lib = make_library(tmp_path / "lib", 1)
    argv = ["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "o.npz"), "--from", str(path)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Assembly.merges" in err[0] and "cycle" in err[0], err
    assert not (tmp_path / "o.npz").exists()


def test_sessions_with_a_cyclic_snapshot_or_journal_entry_are_moved_to_damaged(tmp_path, caplog):
    folder = tmp_path / "state" / "sessions"
    good = Assembly(ALL[:2], (), links("ab"))
    for sid, where in (("aa01", "snapshot"), ("bb02", "journal")):
        auto = Autosave(folder, sid)
        history = auto.load().apply("add", good)
        auto.snapshot(history)
        if where == "snapshot":
            rewrite_meta(auto.snapshot_path, lambda r: r["history"]["steps"][1]["assembly"]["merges"].extend(LOOP))
        else:
            entry = {"seq": 1, "op": "apply", "revision": 2, "step": {"label": "bad", "assembly": {
                "placements": [{"instance": n, "example_id": "ex-0", "T_world_example": {"$array": "T"}} for n in "ab"],
                "merges": [{"a": "a", "b": "b", "vertex_a": 1, "vertex_b": 1}, *LOOP]}},
                "arrays": {"T": ["<f8", [4, 4], np.eye(4).tobytes()]}}
            append_entry(auto.journal_path, entry)
    ok = Autosave(folder, "cc03")
    ok.snapshot(ok.load().apply("add", good))
    with caplog.at_level(logging.ERROR, logger="arboretum.sessions"):
        sessions = Sessions(tmp_path / "state")
    assert [s.id for s in sessions.all()] == ["cc03"]
    assert [(m.a, m.b) for m in sessions.get("cc03").history.assembly.merges] == [("a", "b")]
    assert sorted(p.name for p in (folder / "damaged").iterdir()) == ["aa01.npz", "bb02.journal", "bb02.npz"]
    logged = [r.getMessage() for r in caplog.records]
    assert len(logged) == 2 and all("Assembly.merges" in m and "cycle" in m for m in logged), logged


# -- session.load over the socket ----------------------------------------------------------------------
def request(server: Server, frames: list) -> P.Msg:
    s = zmq.Context.instance().socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.RCVTIMEO, 10_000)
    s.connect(server.endpoint)
    try:
        s.send_multipart(frames)
        return P.parse(s.recv_multipart())[1]
    finally:
        s.close(0)


def load_frames(merges: list[dict]) -> list:
    """session.load frames of placements a, b, c with ``merges`` written into the message (no client
    can build such an Assembly any more; an old client or a hand-made message can still send one)."""
    a = Assembly(tuple(Placement(n, "ex-0", make_transform(t=[0, 0, 0.2 * i])) for i, n in enumerate("abc")))
    frames = P.to_frames(P.SessionLoad(assembly=a, name="x"), 7)
    head = msgpack.unpackb(bytes(frames[0]), raw=False)
    head["body"]["assembly"]["merges"] = merges
    return [msgpack.packb(head, use_bin_type=True), *frames[1:]]


def link(a: str, b: str) -> dict:
    return {"a": a, "b": b, "vertex_a": 1, "vertex_b": 1}


@pytest.mark.timeout(60)
def test_session_load_of_a_cycle_or_double_merge_is_one_clear_error_reply(served):
    cases = {"cycle": [link("a", "b"), link("b", "c"), link("c", "a")],
             "'c' is merged into two placements ('a' and 'b')": [link("a", "c"), link("b", "c")]}
    for words, merges in cases.items():
        reply = request(served, load_frames(merges))
        assert isinstance(reply, P.Error) and reply.code == "protocol", reply
        assert reply.message.startswith("session.load.assembly: not a valid Assembly: Assembly.merges: ")
        assert words in reply.message and "\n" not in reply.message
    info = request(served, load_frames([link("a", "b"), link("b", "c")]))
    assert isinstance(info, P.SessionInfo) and info.placements == 3
    got = request(served, P.to_frames(P.SessionGet(session=info.session), 8))
    assert [(m.a, m.b) for m in got.assembly.merges] == [("a", "b"), ("b", "c")]


# -- every edit keeps a forest, and it survives the store ----------------------------------------------
def random_edit(rng: np.random.Generator, sid: str, names: list[str]) -> P.Request:
    """An add (often), move, delete, undo or redo; placements land near others' main branches (vertical
    from the origin, 1.2-1.8 m long), so recombination links them."""
    kind = str(rng.choice(["add", "add", "move", "delete", "undo", "redo"])) if names else "add"
    T = make_transform(t=[rng.normal(0, 0.02), rng.normal(0, 0.02), rng.uniform(0, 1.2)])
    if kind == "add":
        return P.AddExample(session=sid, example_id=f"ex-{rng.integers(2)}", T_world_example=T)
    if kind == "move":
        return P.TransformExample(session=sid, instance=str(rng.choice(names)), T_world_example=T)
    if kind == "delete":
        return P.DeleteExample(session=sid, instance=str(rng.choice(names)))
    return P.Undo(session=sid) if kind == "undo" else P.Redo(session=sid)


def test_random_edits_with_recombination_are_never_refused_and_reload(tmp_path):
    ctx = Context(Sessions(tmp_path / "state"), make_library(tmp_path / "lib", 2))
    d = Dispatcher(ctx)
    rng = np.random.default_rng(11)
    sid = d.run(P.SessionNew()).session
    merged = 0
    for _ in range(60):
        req = random_edit(rng, sid, [p.instance for p in ctx.sessions.get(sid).history.assembly.placements])
        reply = d.run(req)
        assert isinstance(reply, P.Edit) or (isinstance(req, P.Undo | P.Redo) and "nothing to" in reply.message), reply
        merged = max(merged, len(ctx.sessions.get(sid).history.assembly.merges))
    before = ctx.sessions.get(sid).history
    ctx.close()
    assert merged >= 3  # recombination did link placements, often
    again = Sessions(tmp_path / "state")
    after = again.get(sid).history
    assert not (tmp_path / "state" / "sessions" / "damaged").exists()
    assert [s.label for s in after.steps] == [s.label for s in before.steps] and after.index == before.index
    assert [[(m.a, m.b) for m in s.assembly.merges] for s in after.steps] == \
        [[(m.a, m.b) for m in s.assembly.merges] for s in before.steps]
