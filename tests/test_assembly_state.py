"""Session history: undo/redo as records, journal + snapshot autosave that survives a torn tail."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.assembly import Assembly, Placement
from arboretum_library.errors import InputError
from arboretum_library.geometry import make_transform
from arboretum_server.assembly import state
from arboretum_server.assembly.state import Autosave, History


def placed(*xs: float) -> Assembly:
    return Assembly(tuple(Placement(f"p{i}", "ex", make_transform(t=[x, 0, 0])) for i, x in enumerate(xs)))


def test_undo_redo_move_a_cursor_and_apply_drops_redo():
    h = History().apply("a", placed(1)).apply("b", placed(1, 2))
    assert (h.index, h.revision, len(h.assembly.placements)) == (2, 2, 2)
    h = h.undo()
    assert len(h.assembly.placements) == 1 and h.can_redo and h.revision == 3
    h = h.apply("c", placed(5))
    assert not h.can_redo and h.assembly.placements[0].T_world_example[0, 3] == 5
    with pytest.raises(InputError, match="nothing to redo"):
        h.redo()
    with pytest.raises(InputError, match="nothing to undo"):
        History().undo()


def test_history_is_bounded(monkeypatch):
    monkeypatch.setattr(state, "MAX_STEPS", 5)
    h = History()
    for i in range(9):
        h = h.apply(f"e{i}", placed(i))
    assert len(h.steps) == 5 and h.steps[0].label == "e4" and h.revision == 9


def replay_equal(a: History, b: History) -> None:
    assert (a.index, a.revision, a.name) == (b.index, b.revision, b.name)
    assert [s.label for s in a.steps] == [s.label for s in b.steps]
    for sa, sb in zip(a.steps, b.steps):
        ta = [p.T_world_example for p in sa.assembly.placements]
        tb = [p.T_world_example for p in sb.assembly.placements]
        assert len(ta) == len(tb) and all(np.array_equal(x, y) for x, y in zip(ta, tb))


def test_journal_replays_every_committed_edit(tmp_path):
    auto = Autosave(tmp_path, "abc")
    h = History()
    for i in range(5):
        h = h.apply(f"move {i}", placed(i, 0.5 * i))
        auto.record(h, "apply")
    h = h.undo()
    auto.record(h, "undo")
    back = Autosave(tmp_path, "abc").load()
    replay_equal(back, h)


def test_snapshot_then_journal(tmp_path, monkeypatch):
    monkeypatch.setattr(state, "SNAPSHOT_EVERY", 3)
    auto = Autosave(tmp_path, "s1")
    h = History()
    for i in range(7):
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
        auto.wait()
    assert auto.snapshot_path.exists() and not auto.old_journal_path.exists()
    assert len(state._read_journal(auto.journal_path)[0]) == 1  # 7 = 2 snapshots of 3, then 1
    replay_equal(Autosave(tmp_path, "s1").load(), h)


def test_a_snapshot_that_never_finished_loses_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(state, "SNAPSHOT_EVERY", 3)
    def fail(*a, **k):
        raise OSError("disk full")  # or killed while writing it

    monkeypatch.setattr(state, "save_record", fail)
    auto = Autosave(tmp_path, "s2")
    h = History()
    for i in range(8):
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
        auto.wait()
    assert auto.old_journal_path.exists() and not auto.snapshot_path.exists()
    replay_equal(Autosave(tmp_path, "s2").load(), h)


def test_a_torn_journal_tail_is_ignored_and_cut(tmp_path):
    auto = Autosave(tmp_path, "t")
    h = History()
    for i in range(3):
        h = h.apply(f"e{i}", placed(i))
        auto.record(h, "apply")
    good = auto.journal_path.stat().st_size
    with open(auto.journal_path, "ab") as fh:
        fh.write(b"\x40\x00\x00\x00garbage-that-was-cut-off")
    again = Autosave(tmp_path, "t")
    back = again.load()
    replay_equal(back, h)
    assert auto.journal_path.stat().st_size == good
    h2 = back.apply("after", placed(9))
    again.record(h2, "apply")
    replay_equal(Autosave(tmp_path, "t").load(), h2)
