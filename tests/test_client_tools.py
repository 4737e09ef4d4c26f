"""Tools over the in-memory FakeSession: hand events -> actions -> session state (no GL, no sockets)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from arboretum_client.assembly_view import rigid
from arboretum_client.input.hands import RIGHT, HandEvent, HandSample
from arboretum_client.net import Worker
from arboretum_client.session_fake import FakeSession
from arboretum_client.session_port import SessionPort
from arboretum_client.tools.actions import Actions
from arboretum_client.tools.interaction import Interaction
from arboretum_client.tools.state import REFINEMENT, ClientState
from arboretum_client.tools.view import build_scene


@pytest.fixture
def rig():
    fake = FakeSession()
    state = ClientState()
    worker = Worker(lambda: fake)
    actions = Actions(state, worker, clock=lambda: 0.0)
    tools = Interaction(state, actions)
    yield fake, state, worker, actions, tools
    worker.close()


def ev(kind, position=(0, 0, 0), delta=None):
    return HandEvent(RIGHT, kind, HandSample(RIGHT, rigid(None, position)), delta)


def settle(worker):
    assert worker.wait_idle(10)


def test_fake_session_satisfies_the_port_protocol():
    assert isinstance(FakeSession(), SessionPort)


def test_select_on_empty_space_places_the_chosen_example_then_selects_it(rig):
    fake, state, worker, actions, tools = rig
    actions.choose("oak-0001")
    tools.handle(ev("select", (0.5, 0.25, 1.0)), None)
    settle(worker)
    (p,) = state.assembly.placements
    assert p.example_id == "oak-0001" and np.allclose(p.T_world_example[:3, 3], [0.5, 0.25, 0.0])
    assert "oak-0001" in state.examples and state.revision == 1
    tools.handle(ev("select"), f"inst:{p.instance}/branch:2")
    assert state.selection == [f"inst:{p.instance}"]
    tools.handle(ev("select"), f"inst:{p.instance}/lobe:1")
    assert state.selection == [f"inst:{p.instance}/lobe:1"]


def test_grip_on_a_branch_moves_the_example_and_on_a_lobe_moves_the_lobe(rig):
    fake, state, worker, actions, tools = rig
    actions.add_example("oak-0002", np.eye(4))
    settle(worker)
    inst = state.assembly.placements[0].instance
    move = rigid(None, (1.0, 0.0, 0.0))
    tools.handle(ev("grip_start"), f"inst:{inst}/branch:0")
    tools.handle(ev("grip_move", delta=move), None)
    assert tools.drags[RIGHT].name.endswith("branch:0")
    tools.handle(ev("grip_end", delta=move), None)
    settle(worker)
    assert np.allclose(state.assembly.placements[0].T_world_example[:3, 3], [1, 0, 0])
    tools.handle(ev("grip_start"), f"inst:{inst}/lobe:2")
    tools.handle(ev("grip_end", delta=rigid(None, (0, 0, 0.5))), None)
    settle(worker)
    (lt,) = state.assembly.placements[0].lobe_transforms
    assert lt.lobe == 2 and np.allclose(lt.T_example_lobe[:3, 3], [0, 0, 0.5])
    assert fake.calls.count("transform_example") == 1 and fake.calls.count("transform_lobe") == 1


def test_recombination_feedback_flashes_the_merged_examples(rig):
    fake, state, worker, actions, tools = rig
    actions.add_example("oak-0001", np.eye(4))
    actions.add_example("pine-0001", rigid(None, (0.05, 0.0, 0.6)))
    settle(worker)
    assert len(state.assembly.merges) == 1 and "merged with oak-0001#1" in state.status
    assert set(state.merged_flash) == {"oak-0001#1", "pine-0001#1"}
    scene, _ = build_scene(state, now=1.0)
    yellow = [it for it in scene.items if hasattr(it, "color") and np.allclose(it.color[:3], (1.0, 0.85, 0.1))]
    assert len(yellow) >= 3  # two flashing main branches and the merge link


def test_long_press_strokes_then_touchpad_sketches_a_new_example(rig):
    fake, state, worker, actions, tools = rig
    tools.handle(ev("sketch_start", (0, 0, 0)), None)
    for z in np.linspace(0.1, 1.0, 6):
        tools.handle(ev("sketch_move", (0, 0, z)), None)
    tools.handle(ev("sketch_end", (0, 0, 1.0)), None)
    ring = 0.15 * np.c_[np.cos(np.linspace(0, 2 * np.pi, 10)), np.sin(np.linspace(0, 2 * np.pi, 10)), np.zeros(10)]
    tools.handle(ev("sketch_start", ring[0] + (0.3, 0, 1)), None)
    for p in ring[1:]:
        tools.handle(ev("sketch_move", p + (0.3, 0, 1)), None)
    tools.handle(ev("sketch_end", ring[-1] + (0.3, 0, 1)), None)
    assert len(state.strokes) == 2
    tools.handle(ev("touchpad"), None)
    settle(worker)
    assert state.strokes == [] and len(state.assembly.sketches) == 1
    assert "strokes: branch, lobe" in state.status
    sk = state.assembly.sketches[0]
    assert len(sk.structure.lobes) == 1 and np.allclose(sk.structure.branches[0].points[-1], [0, 0, 1])


def test_menu_deletes_the_selection_and_undo_redo_restore_it(rig):
    fake, state, worker, actions, tools = rig
    actions.add_example("oak-0003", np.eye(4))
    settle(worker)
    state.selection = ["inst:oak-0003#1"]
    tools.handle(ev("menu"), None)
    settle(worker)
    assert state.assembly.placements == () and state.selection == []
    actions.undo()
    settle(worker)
    assert [p.instance for p in state.assembly.placements] == ["oak-0003#1"] and state.can_redo
    actions.redo()
    settle(worker)
    assert state.assembly.placements == ()


def test_refinement_remove_merge_split_insert_and_undo(rig):
    fake, state, worker, actions, tools = rig
    state.mode = REFINEMENT
    actions.refine_open(np.zeros((0, 3)))
    settle(worker)
    n = len(state.draft.lobes)
    assert n >= 4 and state.cloud is not None and len(state.cloud.points) == len(state.draft.points)
    tools.handle(ev("select"), "lobe:0")
    tools.handle(ev("menu"), None)
    settle(worker)
    assert len(state.draft.lobes) == n - 1
    tools.handle(ev("select"), "lobe:0")
    tools.handle(ev("select"), "lobe:1")
    tools.handle(ev("touchpad"), None)
    settle(worker)
    assert len(state.draft.lobes) == n - 2  # two became one
    merged = state.draft.lobes[-1]
    tools.handle(ev("select"), f"lobe:{len(state.draft.lobes) - 1}")
    a, b = merged.points[merged.points[:, 0].argmin()], merged.points[merged.points[:, 0].argmax()]
    state.strokes = [np.stack([a, a + 1e-3]), np.stack([b, b + 1e-3])]
    tools.touchpad()
    settle(worker)
    assert len(state.draft.lobes) == n - 1  # split into two
    # insert: a stroke over cloud points with no lobe selected selects the points near it
    c = state.cloud.points[:5].astype(float)
    tools.handle(ev("sketch_start", c[0]), None)
    for p in c[1:]:
        tools.handle(ev("sketch_move", p), None)
    tools.handle(ev("sketch_end", c[-1]), None)
    assert len(state.point_selection) >= 5
    tools.touchpad()
    settle(worker)
    assert len(state.draft.lobes) == n
    actions.undo()
    settle(worker)
    assert len(state.draft.lobes) == n - 1


def test_show_one_example_and_hide_points_change_the_scene(rig):
    fake, state, worker, actions, tools = rig
    state.mode = REFINEMENT
    actions.refine_open(np.zeros((0, 3)))
    settle(worker)
    full, _ = build_scene(state)
    state.show_all, state.focus = False, 1
    one, _ = build_scene(state)
    state.show_points = False
    bare, _ = build_scene(state)
    assert len(bare.items) == len(one.items) - 1 < len(full.items) - 1
    assert "points" in full.names.values() and "points" not in bare.names.values()


def test_grow_and_export_use_the_density_and_write_the_file(rig, tmp_path):
    fake, state, worker, actions, tools = rig
    actions.add_example("oak-0001", np.eye(4))
    actions.set_density(0.5)
    actions.grow()
    settle(worker)
    few = len(state.grown.leaf_centres)
    actions.set_density(2.0)
    actions.grow()
    actions.export(tmp_path, "obj")
    settle(worker)
    assert len(state.grown.leaf_centres) == 4 * few
    text = (tmp_path / "tree.obj").read_text()
    assert text.count("\nl ") + text.startswith("l ") == 5  # one polyline per branch of oak-0001


def test_save_and_load_round_trip_the_assembly(rig, tmp_path):
    fake, state, worker, actions, tools = rig
    actions.add_example("pine-0002", rigid(None, (1, 1, 0)))
    actions.save(tmp_path / "s.npz")
    settle(worker)
    actions.delete_example("pine-0002#1")
    settle(worker)
    actions.load(tmp_path / "s.npz")
    settle(worker)
    assert [p.instance for p in state.assembly.placements] == ["pine-0002#1"]


class SlowPort(FakeSession):
    def __init__(self, gate: threading.Event) -> None:
        super().__init__()
        self.gate = gate

    def list_library(self, species="", tags=()):
        self.gate.wait(10)
        return super().list_library(species, tags)


def test_the_worker_never_blocks_the_frame_loop_and_reports_errors():
    gate = threading.Event()
    state = ClientState()
    worker = Worker(lambda: SlowPort(gate))
    actions = Actions(state, worker)
    try:
        actions.refresh_library()
        t = time.perf_counter()
        for _ in range(100):
            worker.drain()
        assert time.perf_counter() - t < 0.05 and state.library == [] and len(worker.running) == 1
        gate.set()
        assert worker.wait_idle(10) and len(state.library) == 6
        actions.remove_lobe(0)  # no draft: the fake raises InputError -> a status line, not a crash
        assert worker.wait_idle(10)
        assert state.errors and "open a scan first" in state.errors[-1]
    finally:
        gate.set()
        worker.close()


def test_search_and_tag_filter(rig):
    fake, state, worker, actions, tools = rig
    actions.search("pine straight")
    settle(worker)
    ids = [r["id"] for r in state.library]
    assert ids[0] == "pine-0001" and len(ids) == 5  # both terms first; oak-0002 matches neither
    assert all(r["species"] == "pine" or "straight" in r["tags"] for r in state.library)
    state.tag_filter = "sparse"
    actions.refresh_library()
    settle(worker)
    assert sorted(r["id"] for r in state.library) == ["oak-0003", "pine-0001", "pine-0003"]


class GatedGrow(FakeSession):
    def __init__(self, gate: threading.Event) -> None:
        super().__init__()
        self.gate = gate

    def grow(self, seed=0, options=None, progress=None):
        progress(1, 4, "colonising")
        self.gate.wait(10)
        return super().grow(seed, options, progress)


def test_a_long_job_shows_its_progress_bar_in_the_status_bar():
    from arboretum_client.ui.layout import draw_ui

    gate = threading.Event()
    state = ClientState()
    worker = Worker(lambda: GatedGrow(gate))
    actions = Actions(state, worker)
    try:
        actions.add_example("oak-0001", np.eye(4))
        assert worker.wait_idle(10)
        actions.grow()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not any(j.fraction for j in worker.running.values()):
            worker.drain()
            time.sleep(0.005)
        (job,) = worker.running.values()
        assert job.name == "grow" and job.fraction == 0.25 and job.message == "colonising"
        img = draw_ui((800, 400), state, worker.running).rgba()
        bar = img[400 - 26 - 22 + 3:400 - 26 - 4, 230:530, :3].astype(int)
        filled = (np.abs(bar - (90, 160, 255)).sum(axis=2) < 30).mean(axis=0)
        assert 0.2 < (filled > 0.5).mean() < 0.3  # a quarter of the bar is filled
        gate.set()
        assert worker.wait_idle(10) and state.grown is not None
    finally:
        gate.set()
        worker.close()


def test_grip_with_a_scale_gesture_scales_the_example_and_the_lobe(rig):
    fake, state, worker, actions, tools = rig
    actions.add_example("oak-0001", np.eye(4))
    settle(worker)
    inst = state.assembly.placements[0].instance
    tools.handle(ev("grip_start"), f"inst:{inst}/branch:0")
    tools.handle(HandEvent(RIGHT, "grip_end", HandSample(RIGHT), np.eye(4), 1.5), None)
    settle(worker)
    assert state.assembly.placements[0].scale == pytest.approx(1.5)
    tools.handle(ev("grip_start"), f"inst:{inst}/lobe:0")
    tools.handle(HandEvent(RIGHT, "grip_end", HandSample(RIGHT), np.eye(4), 0.5), None)
    settle(worker)
    (lt,) = state.assembly.placements[0].lobe_transforms
    assert np.allclose(lt.T_example_lobe[:3, :3], 0.5 * np.eye(3))


def test_menu_with_nothing_selected_browses_the_library(rig):
    fake, state, worker, actions, tools = rig
    actions.refresh_library()
    settle(worker)
    ids = [r["id"] for r in state.library]
    tools.handle(ev("menu"), None)
    tools.handle(ev("menu"), None)
    settle(worker)
    assert state.chosen == ids[1] and ids[1] in state.examples
    tools.handle(ev("select", (1.0, 1.0, 0.5)), None)
    settle(worker)
    assert [p.example_id for p in state.assembly.placements] == [ids[1]]
