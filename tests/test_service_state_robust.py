"""Server state under damage and hostile values: cut snapshots, a kill mid-snapshot, a session closed
while its job runs, fsync of snapshots, out-of-range placements and oversized stroke requests."""

from __future__ import annotations

import io
import logging
import os
import shutil
import threading

import msgpack
import numpy as np
import pytest

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly, LobeTransform, Placement
from arboretum_library.cli import main
from arboretum_library.codec import (
    arrays_to_npz,
    load_record,
    npz_to_arrays,
    save_record,
    unflatten,
)
from arboretum_library.errors import InputError, ProtocolError, ValidationError
from arboretum_library.geometry import make_transform
from arboretum_server.assembly import state
from arboretum_server.assembly.state import Autosave, History
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher
from arboretum_server.service.handlers import assembly as assembly_handlers
from arboretum_server.service.sessions import Sessions
from factories import make_library, reply_of


def placed(*xs: float) -> Assembly:
    return Assembly(tuple(Placement(f"p{i}", "ex", make_transform(t=[x, 0, 0])) for i, x in enumerate(xs)))


def same(a: History, b: History) -> None:
    assert (a.index, a.revision, [s.label for s in a.steps]) == (b.index, b.revision, [s.label for s in b.steps])
    assert np.array_equal(a.assembly.placements[0].T_world_example, b.assembly.placements[0].T_world_example)


@pytest.fixture
def server(tmp_path):
    ctx = Context(Sessions(tmp_path / "state"), make_library(tmp_path / "lib", 2))
    yield Dispatcher(ctx)
    ctx.close()


ok = reply_of


def err(d: Dispatcher, req: P.Request, code: str, match: str) -> P.Error:
    reply = d.run(req)
    assert isinstance(reply, P.Error) and reply.code == code and match in reply.message, reply
    return reply


# -- 1: damaged snapshots ------------------------------------------------------------------------------
def test_any_damaged_npz_is_one_validation_error():
    rng = np.random.default_rng(0)
    arrays = {"a": rng.random((30, 3)), "b": np.arange(50), "__meta__": np.frombuffer(b'{"k": 1}' * 4, np.uint8)}
    kinds = set()
    for compress in (False, True):
        good = arrays_to_npz(arrays, compress=compress)
        cases = [good[:cut] for cut in range(0, len(good), 7)]
        for _ in range(1500):
            b = bytearray(good)
            for pos in rng.integers(0, len(b), int(rng.integers(1, 4))):
                b[pos] = int(rng.integers(256))
            cases.append(bytes(b))
        for data in cases:
            try:
                npz_to_arrays(data, "x.npz")
                kinds.add("read")
            except ValidationError as exc:
                assert str(exc).startswith("x.npz: not a readable .npz")
                kinds.add("refused")
    assert kinds == {"read", "refused"}


def test_a_cut_record_file_is_one_input_error(tmp_path):
    path = save_record(tmp_path / "a.npz", placed(1.0))
    os.truncate(path, path.stat().st_size // 2)
    with pytest.raises(InputError, match="damaged or cut short"):
        load_record(path, Assembly)


def test_assemble_from_a_cut_session_is_one_clear_error(tmp_path, capsys):
    start = save_record(tmp_path / "s.npz", placed(1.0))
    os.truncate(start, start.stat().st_size // 2)
    (tmp_path / "s.yaml").write_text("- undo: {}\n")
    code = main(["assemble", str(tmp_path / "s.yaml"), "--library", str(tmp_path / "lib"),
                 "--out", str(tmp_path / "o.npz"), "--from", str(start)])
    err_text = capsys.readouterr().err
    assert code != 0 and "damaged or cut short" in err_text and "Traceback" not in err_text


def test_a_damaged_session_is_skipped_and_moved_aside(tmp_path, caplog):
    sessions = Sessions(tmp_path)
    keep, bad = sessions.new("keep"), sessions.new("bad")
    bad.commit(bad.history.apply("move", placed(2.0)))
    folder = tmp_path / "sessions"
    snap = folder / f"{bad.id}.npz"
    os.truncate(snap, snap.stat().st_size // 2)
    cut = snap.read_bytes()
    with caplog.at_level(logging.ERROR, "arboretum.sessions"):
        again = Sessions(tmp_path)
    assert [s.id for s in again.all()] == [keep.id]
    assert sorted(p.name for p in (folder / "damaged").iterdir()) == [f"{bad.id}.journal", f"{bad.id}.npz"]
    assert (folder / "damaged" / f"{bad.id}.npz").read_bytes() == cut
    assert not list(folder.glob(f"{bad.id}.*")) and bad.id in caplog.text and "damaged" in caplog.text


# -- 2: a kill during a background snapshot ------------------------------------------------------------
def test_snapshots_resume_after_a_kill_mid_snapshot(tmp_path, monkeypatch):
    monkeypatch.setattr(state, "SNAPSHOT_EVERY", 4)
    live, killed = tmp_path / "live", tmp_path / "killed"
    real_save, gate = state.save_record, threading.Event()

    def stuck(*a, **k):  # the background writer hangs: the process is "killed" while it does
        gate.wait()
        return real_save(*a, **k)

    monkeypatch.setattr(state, "save_record", stuck)
    auto, h = Autosave(live, "k1"), History()
    for i in range(6):  # the 4th edit starts a snapshot that never finishes; two more are journaled
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
    shutil.copytree(live, killed)  # the disk as the kill left it
    gate.set()
    auto.wait()
    monkeypatch.setattr(state, "save_record", real_save)
    assert sorted(p.name for p in killed.iterdir()) == ["k1.journal", "k1.journal.old"]
    back = Autosave(killed, "k1")
    same(back.load(), h)  # every acknowledged edit
    assert not back.old_journal_path.exists() and back.snapshot_path.exists()
    for i in range(6, 14):
        h = h.apply(f"e{i}", placed(i))
        back.record(h, "apply")
        back.wait()
    assert load_record(back.snapshot_path, state.Snapshot).seq == 14 and not back.old_journal_path.exists()
    same(Autosave(killed, "k1").load(), h)


def test_a_failed_background_snapshot_is_retried(tmp_path, monkeypatch):
    monkeypatch.setattr(state, "SNAPSHOT_EVERY", 3)
    real_save, calls = state.save_record, []

    def flaky(*a, **k):
        calls.append(1)
        if len(calls) == 1:
            raise OSError("disk full")
        return real_save(*a, **k)

    monkeypatch.setattr(state, "save_record", flaky)
    auto, h = Autosave(tmp_path, "r1"), History()
    for i in range(7):
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
        auto.wait()
    assert len(calls) == 2 and not auto.old_journal_path.exists()
    assert load_record(auto.snapshot_path, state.Snapshot).seq == 6
    same(Autosave(tmp_path, "r1").load(), h)


def test_a_kill_while_folding_the_journal_into_the_old_one_loses_nothing(tmp_path):
    auto, h = Autosave(tmp_path, "d1"), History()
    for i in range(5):
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
    data = auto.journal_path.read_bytes()
    auto.old_journal_path.write_bytes(data[: len(data) // 3] + b"\x07")  # the older entries, torn tail
    with open(auto.old_journal_path, "ab") as fh:  # then the fold appended the journal, and was killed
        fh.write(data)
    back = Autosave(tmp_path, "d1")
    same(back.load(), h)
    assert not back.old_journal_path.exists() and load_record(back.snapshot_path, state.Snapshot).seq == 5


# -- 3: a session closed while its refine.open job runs ------------------------------------------------
def test_closing_during_refine_open_answers_not_found_and_writes_nothing(server):
    sid = ok(server, P.SessionNew()).session
    job = server.handle(P.RefineOpen(session=sid, points=np.random.default_rng(1).random((50, 3))))
    ok(server, P.SessionClose(session=sid))
    reply = server.finish(job, {"states": ["a decomposition"]}, "refine.open")
    assert isinstance(reply, P.Error) and reply.code == "not_found" and "closed" in reply.message
    assert not list(server.ctx.sessions.dir().glob(f"{sid}*"))


def test_start_up_removes_refine_files_of_sessions_that_are_gone(tmp_path):
    sessions = Sessions(tmp_path)
    live = sessions.new("live")
    folder = tmp_path / "sessions"
    for sid in (live.id, "0123456789abcdef"):
        (folder / f"{sid}.refine.npz").write_bytes(b"source")
        (folder / f"{sid}.refine.journal").write_bytes(b"edits")
    Sessions(tmp_path)
    assert sorted(p.name for p in folder.glob("*.refine.*")) == [f"{live.id}.refine.journal", f"{live.id}.refine.npz"]


# -- 4: --fsync ---------------------------------------------------------------------------------------
def test_fsync_makes_snapshot_rename_and_deletion_durable(tmp_path, monkeypatch):
    monkeypatch.setattr(state, "SNAPSHOT_EVERY", 3)
    events, real = [], {n: getattr(os, n) for n in ("fsync", "replace", "unlink")}

    def fsync(fd):
        events.append(("fsync", os.path.basename(os.readlink(f"/proc/self/fd/{fd}"))))
        return real["fsync"](fd)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", lambda a, b: (events.append(("rename", os.path.basename(b))), real["replace"](a, b))[1])
    monkeypatch.setattr(os, "unlink", lambda p, **k: (events.append(("unlink", os.path.basename(p))), real["unlink"](p, **k))[1])
    auto, h = Autosave(tmp_path / "s", "f1", fsync=True), History()
    for i in range(3):
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
    auto.wait()
    events = [e for e in events if e[0] != "unlink" or not e[1].endswith(".tmp")]  # finally: tmp.unlink
    k = events.index(("rename", "f1.npz"))
    assert events[k - 1][0] == "fsync" and events[k - 1][1].endswith(".tmp")  # the temp file, before
    assert events[k + 1] == ("fsync", "s")  # the folder, after the rename
    assert events[k + 2:k + 4] == [("unlink", "f1.journal.old"), ("fsync", "s")]
    r = events.index(("rename", "f1.journal.old"))
    assert events[r + 1] == ("fsync", "s")  # the retired journal's new name
    assert events[:2] == [("fsync", "f1.journal"), ("fsync", "s")]  # a new journal's name is durable too


# -- 5: values that used to break a session -------------------------------------------------------------
@pytest.mark.parametrize(("kwargs", "match"), [
    ({"scale": 1e308}, "Placement.scale"), ({"scale": 1e-300}, "Placement.scale"), ({"scale": 2e6}, "Placement.scale"),
    ({"T_world_example": make_transform(t=[1e308, 0, 0])}, "translation"),
    ({"T_world_example": make_transform(t=[0, 2e7, 0])}, "translation"),
])
def test_placement_values_are_bounded(kwargs, match):
    args = {"instance": "a", "example_id": "ex", "T_world_example": np.eye(4), **kwargs}
    with pytest.raises(ValidationError, match=match):
        Placement(**args)
    assert Placement("a", "ex", make_transform(t=[5.5e6, 0, 0]), 1e6).scale == 1e6  # a UTM northing
    assert Placement("a", "ex", np.eye(4), 0.0005).scale == 0.0005  # legal in sessions saved before the bound


def test_lobe_transforms_must_be_bounded_similarities():
    with pytest.raises(ValidationError, match="scale"):
        LobeTransform(0, np.diag([0.0, 0, 0, 1]))
    with pytest.raises(ValidationError, match="uniform scale"):
        LobeTransform(0, np.diag([1.0, 2, 1, 1]))
    with pytest.raises(ValidationError, match="lobe"):
        LobeTransform(-1, np.eye(4))
    assert LobeTransform(2, np.diag([2.0, 2, 2, 1])).lobe == 2


@pytest.mark.parametrize("bad", [float("inf"), 1e300, 1.5, True, "3", 2**63])
def test_integer_fields_take_whole_numbers_within_int64(bad):
    meta = {"lobe": bad, "T_example_lobe": {"$array": "T"}}
    with pytest.raises(ValidationError, match=r"LobeTransform\.lobe: .* not a valid integer"):
        unflatten(LobeTransform, meta, {"T": np.eye(4)})
    assert unflatten(LobeTransform, {**meta, "lobe": 3.0}, {"T": np.eye(4)}).lobe == 3


def session_load_frames(assembly: Assembly, edit) -> list:
    frames = P.to_frames(P.SessionLoad(assembly=assembly, name="x"), 7)
    head = msgpack.unpackb(bytes(frames[0]), raw=False)
    edit(head["body"]["assembly"])
    return [msgpack.packb(head, use_bin_type=True), *frames[1:]]


def test_session_load_refuses_huge_lobe_index_and_bad_links(server):
    a = Assembly((Placement("a", "ex-0", np.eye(4), 1.0, (LobeTransform(1, np.eye(4)),)),
                  Placement("b", "ex-1", make_transform(t=[0.5, 0, 0]))))
    for value in (1e300, float("inf")):
        frames = session_load_frames(a, lambda m, v=value: m["placements"][0]["lobe_transforms"][0].update(lobe=v))
        with pytest.raises(ProtocolError, match=r"placements\[0\]\.lobe_transforms\[0\]\.lobe"):
            P.parse(frames)
    far = Assembly((Placement("a", "ex-0", np.eye(4), 1.0, (LobeTransform(2**40, np.eye(4)),)),))
    err(server, P.SessionLoad(assembly=far), "bad_input", "lobe_transforms[0].lobe")
    loop = [{"a": "a", "b": "b", "vertex_a": 1, "vertex_b": 1}, {"a": "b", "b": "a", "vertex_a": 1, "vertex_b": 1}]
    with pytest.raises(ProtocolError, match=r"^session\.load\.assembly: not a valid Assembly: Assembly\.merges: .* cycle"):
        P.parse(session_load_frames(a, lambda m: m.update(merges=loop)))
    info = ok(server, P.SessionLoad(assembly=a))
    assert np.isfinite(ok(server, P.SessionHBL(session=info.session)).hbl.branches[0].points).all()


def test_largest_accepted_placement_still_assembles(server):
    sid = ok(server, P.SessionNew()).session
    ok(server, P.AddExample(session=sid, example_id="ex-0", T_world_example=make_transform(t=[1e7, -1e7, 1e7]),
                            scale=1e6))
    hbl = ok(server, P.SessionHBL(session=sid)).hbl
    assert np.isfinite(hbl.branches[0].points).all() and np.isclose(hbl.root[0], 1e7)
    err(server, P.AddExample(session=sid, example_id="ex-0", T_world_example=np.eye(4), scale=1e308),
        "bad_input", "Placement.scale")


# -- 6: oversized inline stroke requests -----------------------------------------------------------------
def test_stroke_limits_are_checked_before_any_work(server, monkeypatch):
    calls = []
    monkeypatch.setattr(assembly_handlers, "recognise", lambda s: calls.append(1) or "branch")
    sid = ok(server, P.SessionNew()).session
    k = assembly_handlers.MAX_STROKES + 1
    pts, sizes = np.zeros((2 * k, 3)), np.full(k, 2)
    err(server, P.RecognizeStrokes(stroke_points=pts, stroke_sizes=sizes), "bad_input", "at most 10000")
    n = assembly_handlers.MAX_STROKE_POINTS + 1
    err(server, P.RecognizeStrokes(stroke_points=np.zeros((n, 3)), stroke_sizes=np.array([n])),
        "bad_input", "at most 1000000")
    k = assembly_handlers.MAX_SKETCH_STROKES + 1
    err(server, P.SketchExample(session=sid, stroke_points=np.zeros((2 * k, 3)), stroke_sizes=np.full(k, 2)),
        "bad_input", "at most 1000 are taken")
    err(server, P.SplitLobe(session=sid, lobe=0, stroke_points=pts[:4], stroke_sizes=np.array([2, 2**62])),
        "bad_input", "stroke sizes")
    err(server, P.SplitLobe(session=sid, lobe=0, stroke_points=pts[:202], stroke_sizes=np.full(101, 2)),
        "bad_input", "101 strokes, at most 100")
    assert calls == []
    assert ok(server, P.RecognizeStrokes(stroke_points=np.eye(3)[:2], stroke_sizes=np.array([2]))).kinds == ("branch",)


def test_strokes_far_out_or_too_long_are_clear_errors(server):
    sid = ok(server, P.SessionNew()).session
    huge = np.array([[0, 0, 0], [0, 0, 1e300], [0, 1e300, 1e300]], float)
    err(server, P.SketchExample(session=sid, stroke_points=huge, stroke_sizes=np.array([3])), "bad_input", "1e+07 m")
    err(server, P.RecognizeStrokes(stroke_points=huge, stroke_sizes=np.array([3])), "bad_input", "stroke sample")
    long = np.array([[0, 0, 0], [0, 0, 2e4]], float)
    err(server, P.SketchExample(session=sid, stroke_points=long, stroke_sizes=np.array([2])), "bad_input", "long together")


def test_journal_and_npz_files_are_unchanged_by_the_fsync_flag(tmp_path):
    a, b = save_record(tmp_path / "a.npz", placed(1.0)), save_record(tmp_path / "b.npz", placed(1.0), fsync=True)
    assert npz_to_arrays(a.read_bytes()).keys() == npz_to_arrays(io.BytesIO(b.read_bytes())).keys()
    assert a.read_bytes() == b.read_bytes()
