"""The two-hands model, the desktop backend and the grip-drag maths (pure numpy, no GL, no network)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_client.assembly_view import placed_hbl, rigid, rot_z
from arboretum_client.camera import Camera
from arboretum_client.demo import demo_example
from arboretum_client.input.desktop import DesktopInput, Key, MouseButton, MouseMove, cursor_ray
from arboretum_client.input.hands import LEFT, LONG_PRESS, RIGHT, Hands, HandSample, HandTracker
from arboretum_client.tools.gizmo import drag_example, drag_lobe
from arboretum_library.assembly import LobeTransform, Placement


def pose(p, yaw=0.0):
    return rigid(rot_z(yaw), p)


def run(tracker, frames):
    """frames: list of (t, position, buttons) -> all events' kinds."""
    out = []
    for t, p, b in frames:
        out += tracker.update(HandSample(RIGHT, pose(p), buttons=frozenset(b)), t)
    return out


def test_short_trigger_press_selects_and_long_press_sketches():
    short = run(HandTracker(RIGHT), [(0.0, (0, 0, 0), ()), (0.1, (0, 0, 0), {"trigger"}), (0.2, (0, 0, 0), ())])
    assert [e.kind for e in short] == ["select"]
    t = [0.0, 0.1, 0.1 + LONG_PRESS + 0.01, 0.6, 0.7, 0.8]
    b = [(), {"trigger"}, {"trigger"}, {"trigger"}, {"trigger"}, ()]
    long = run(HandTracker(RIGHT), [(ti, (ti, 0, 0), bi) for ti, bi in zip(t, b)])
    assert [e.kind for e in long] == ["sketch_start", "sketch_move", "sketch_move", "sketch_move", "sketch_end"]
    assert np.allclose(long[0].sample.position, [0.1, 0, 0])  # the stroke starts where the trigger went down
    assert np.allclose(long[-1].sample.position, [0.8, 0, 0])


def test_grip_reports_the_rigid_delta_since_the_press():
    tr = HandTracker(LEFT)
    tr.update(HandSample(LEFT, pose((1, 0, 0))), 0.0)
    start = tr.update(HandSample(LEFT, pose((1, 0, 0)), buttons=frozenset({"grip"})), 0.1)
    move = tr.update(HandSample(LEFT, pose((1, 2, 0), np.pi / 2), buttons=frozenset({"grip"})), 0.2)
    end = tr.update(HandSample(LEFT, pose((1, 2, 0), np.pi / 2)), 0.3)
    assert [e.kind for e in start + move + end] == ["grip_start", "grip_move", "grip_end"]
    d = move[0].delta
    # a point held in the hand (at the hand) follows it: delta @ start = now
    assert np.allclose(d @ pose((1, 0, 0)), pose((1, 2, 0), np.pi / 2))


def test_touchpad_and_menu_fire_once_per_press_and_hands_are_independent():
    hands = Hands()
    a = hands.update([HandSample(LEFT, buttons=frozenset({"menu"})), HandSample(RIGHT, buttons=frozenset({"touchpad"}))], 0)
    b = hands.update([HandSample(LEFT, buttons=frozenset({"menu"})), HandSample(RIGHT, buttons=frozenset({"touchpad"}))], 0.1)
    assert sorted((e.side, e.kind) for e in a) == [(LEFT, "menu"), (RIGHT, "touchpad")] and b == []


def test_cursor_ray_passes_through_the_projected_point():
    cam = Camera(target=(0.2, 0.1, 1.0), distance=3.0, azimuth=-40, elevation=20)
    p = np.array([0.5, -0.3, 1.4])
    x, y = cam.project(p[None], (640, 480))[0]
    origin, d = cursor_ray(cam, (640, 480), x, y)
    off = (p - origin) - np.dot(p - origin, d) * d
    assert np.linalg.norm(off) < 1e-6 and np.isclose(np.linalg.norm(d), 1.0)


def test_desktop_mouse_drives_the_right_hand_and_ctrl_the_left():
    cam = Camera(target=(0, 0, 1), distance=4.0)
    desk = DesktopInput(cam, (640, 480))
    desk.handle(MouseMove(100, 200))
    desk.handle(MouseButton("left", True))
    s = {h.side: h for h in desk.samples()}
    assert s[RIGHT].buttons == {"trigger"} and s[LEFT].buttons == frozenset() and not s[LEFT].tracked
    assert np.allclose(cam.project(s[RIGHT].position[None], (640, 480))[0], (100, 200), atol=1e-6)
    desk.handle(MouseButton("left", False))
    desk.handle(Key("ctrl", True))
    desk.handle(MouseMove(300, 100))
    desk.handle(MouseButton("right", True))
    s = {h.side: h for h in desk.samples()}
    assert s[LEFT].buttons == {"grip"} and s[LEFT].tracked and s[RIGHT].buttons == frozenset()


def test_desktop_orbit_zoom_and_fly():
    cam = Camera(target=(0, 0, 1), distance=4.0, azimuth=0, elevation=10)
    desk = DesktopInput(cam, (640, 480))
    desk.handle(MouseButton("middle", True))
    desk.handle(MouseMove(desk.mouse[0] + 100, desk.mouse[1]))
    assert desk.camera.azimuth == pytest.approx(330.0) and desk.camera.distance == 4.0
    desk.handle(MouseButton("middle", False))
    from arboretum_client.input.desktop import Scroll

    desk.handle(Scroll(2))
    assert desk.camera.distance == pytest.approx(4.0 * 0.81)
    desk.handle(Key("f"))
    eye = desk.camera.eye.copy()
    desk.handle(Key("w", True))
    desk.advance(0.5)
    forward = (np.asarray(cam.target) - cam.eye) / np.linalg.norm(np.asarray(cam.target) - cam.eye)
    assert desk.fly and np.dot(desk.camera.eye - eye, forward) > 0.1


def test_drag_example_moves_points_rigidly_with_the_hand():
    T0 = rigid(rot_z(0.3), (1, 2, 0))
    delta = pose((0.5, 0, 0.2), 0.4)
    T1 = drag_example(delta, T0)
    p_example = np.array([0.1, 0.2, 0.3, 1.0])
    assert np.allclose(T1 @ p_example, delta @ (T0 @ p_example))
    assert np.allclose(T1[:3, :3] @ T1[:3, :3].T, np.eye(3))


def test_drag_lobe_moves_the_lobe_centre_by_the_world_translation():
    ex = demo_example("t", 3, n_lobes=3)
    p = Placement("t#1", "t", rigid(rot_z(0.7), (2, 0, 0)), scale=1.5)
    before = placed_hbl(ex.structure, p).lobes[1].centre
    move = rigid(None, (0.1, -0.2, 0.3))
    T = drag_lobe(move, p.T_world_example, p.scale)
    after = placed_hbl(ex.structure, dataclasses.replace(p, lobe_transforms=(LobeTransform(1, T),))).lobes[1].centre
    assert np.allclose(after - before, [0.1, -0.2, 0.3])
    # composing a second drag keeps the first
    T2 = drag_lobe(move, p.T_world_example, p.scale, T)
    again = placed_hbl(ex.structure, dataclasses.replace(p, lobe_transforms=(LobeTransform(1, T2),))).lobes[1].centre
    assert np.allclose(again - before, [0.2, -0.4, 0.6])


def test_the_wheel_scales_while_the_grip_is_held_and_zooms_otherwise():
    from arboretum_client.input.desktop import Scroll

    desk = DesktopInput(Camera(target=(0, 0, 1), distance=4.0), (640, 480))
    desk.handle(MouseMove(320, 240))
    desk.handle(MouseButton("right", True))
    desk.handle(Scroll(2))
    s = {h.side: h for h in desk.samples()}
    assert s[RIGHT].scale == pytest.approx(1.21) and desk.camera.distance == 4.0
    tr = HandTracker(RIGHT)
    tr.update(HandSample(RIGHT, buttons=frozenset({"grip"})), 0.0)
    (end,) = tr.update(HandSample(RIGHT, scale=1.21), 0.1)
    assert end.kind == "grip_end" and end.scale == pytest.approx(1.21)
    desk.handle(MouseButton("right", False))
    desk.handle(Scroll(1))
    assert desk.camera.distance == pytest.approx(3.6)


def test_the_wheel_scale_is_bounded_and_an_out_of_range_preview_draws_nothing():
    # 70 wheel steps took the grip scale past the model's placement range (then 1e-3..1e3): the drag
    # preview raised ValidationError in the main loop (a reviewer's case)
    from arboretum_client.input.desktop import GRIP_SCALE, Scroll
    from arboretum_client.overlay import overlay_scene
    from arboretum_client.tools.interaction import Drag
    from arboretum_client.tools.state import ClientState
    from arboretum_library.assembly import Assembly

    desk = DesktopInput(Camera(target=(0, 0, 1), distance=4.0), (640, 480))
    desk.handle(MouseMove(320, 240))
    desk.handle(MouseButton("right", True))
    for _ in range(80):
        desk.handle(Scroll(1))
    assert {h.side: h for h in desk.samples()}[RIGHT].scale == GRIP_SCALE
    ex = demo_example("oak", 1)
    st = ClientState()
    st.examples[ex.id] = ex
    st.assembly = Assembly(placements=(Placement(f"{ex.id}#1", ex.id, np.eye(4), 50.0),))
    for name in (f"inst:{ex.id}#1/branch:0", f"inst:{ex.id}#1/lobe:1"):
        fine = overlay_scene(st, [], {"right": Drag("right", name, np.eye(4), 2.0)}, 5.0)
        huge = overlay_scene(st, [], {"right": Drag("right", name, np.eye(4), 2e6)}, 5.0)  # past 1e6
        assert len(huge.items) == 0 < len(fine.items)
