"""The VR path against a fake of the small runtime interface: controllers are hands, one render per eye."""

from __future__ import annotations

import math
import tempfile

import numpy as np
import pytest

from arboretum_client.assembly_view import rigid
from arboretum_client.input.hands import LEFT, LONG_PRESS, RIGHT
from arboretum_client.input.openxr import (
    ControllerState,
    EyeCamera,
    EyeView,
    VrSession,
    VrUnavailable,
    XrFrame,
    open_runtime,
    to_hand,
)

FOV = (-0.8, 0.8, 0.7, -0.7)


class FakeRuntime:
    """Yields scripted controller states; two eyes 6 cm apart looking along +Y from y = -3 m."""

    def __init__(self, script: list[tuple[ControllerState, ...]], size=(160, 120)) -> None:
        self.script, self.size = script, size
        self.presented: list[np.ndarray] = []
        self.eyes_rendered = 0

    def frames(self):
        for k, controllers in enumerate(self.script):
            yield XrFrame(k / 90.0, controllers)

    def views(self, frame):
        for dx in (-0.03, 0.03):
            T = np.eye(4)
            T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # eye -Z looks along world +Y, eye +Y is world +Z
            T[:3, 3] = (dx, -3.0, 1.0)
            yield EyeView(T, FOV, self.size)

    def present(self, renderer) -> None:
        self.presented.append(renderer.read())

    def close(self) -> None:
        pass


def ctl(side, p, trigger=0.0, squeeze=0.0, menu=False, click=False):
    return ControllerState(side, rigid(None, p), trigger, squeeze, (0.0, 0.0), click, menu)


def test_controller_state_becomes_a_hand_sample():
    s = to_hand(ControllerState(LEFT, rigid(None, (1, 2, 3)), trigger=0.9, squeeze=0.2, menu=True))
    assert s.side == LEFT and s.buttons == {"trigger", "menu"} and np.allclose(s.position, (1, 2, 3))
    assert np.allclose(s.ray_dir, (0, 0, -1)) and s.pixel is None


def test_eye_camera_projects_like_the_fov_says():
    T = np.eye(4)
    cam = EyeCamera(T, (-math.atan(0.5), math.atan(1.0), math.atan(0.5), -math.atan(0.5)))
    P = cam.projection_matrix() @ cam.view_matrix()
    for point, ndc_x in (((1.0, 0.0, -1.0), 1.0), ((-0.5, 0.0, -1.0), -1.0)):
        clip = P @ np.array([*point, 1.0])
        assert np.isclose(clip[0] / clip[3], ndc_x)


def test_without_a_runtime_open_runtime_is_a_clear_error():
    pytest.importorskip("xr")
    with pytest.raises(VrUnavailable, match="no OpenXR runtime"):
        open_runtime()


@pytest.mark.gl
def test_vr_hands_grip_an_example_and_each_eye_is_rendered():
    from arboretum_client.app import App
    from arboretum_client.headless import OffscreenRenderer
    from arboretum_client.session_fake import FakeSession

    fake = FakeSession()
    t = [0.0]
    with OffscreenRenderer((160, 120)) as off, off.ctx:
        app = App(off.renderer, lambda: fake, out_dir=tempfile.mkdtemp(), clock=lambda: t[0], ui=False)
        app.start()
        app.actions.add_example("oak-0001", np.eye(4))
        assert app.worker.wait_idle(10)
        trunk = app.state.examples["oak-0001"].structure.branches[0].points[4]
        rest = ctl(LEFT, (-1, -1, 0))
        script = [(rest, ctl(RIGHT, trunk))] * 3                                       # touch the trunk
        script += [(rest, ctl(RIGHT, trunk + [0.1 * k, 0, 0], squeeze=1.0)) for k in range(6)]  # grip, move 0.5 m
        script += [(rest, ctl(RIGHT, trunk + [0.5, 0, 0]))] * 2                         # release
        runtime = FakeRuntime(script)
        session = VrSession(app, runtime)

        def tick_clock(orig=app.update):
            t[0] += 1 / 90
            return orig()
        app.update = tick_clock
        assert session.run() == len(script)
        assert app.worker.wait_idle(10)
        app.update()
        assert len(runtime.presented) == 2 * len(script)
        T = app.state.assembly.placements[0].T_world_example
        assert np.allclose(T[:3, 3], [0.5, 0, 0], atol=1e-9) and fake.calls.count("transform_example") == 1
        # the two eyes see the scene from 6 cm apart: similar but not identical images with red branch pixels
        left, right = runtime.presented[-2].astype(int), runtime.presented[-1].astype(int)
        red = (left[..., 0] > 150) & (left[..., 1] < 90)
        assert red.sum() > 20 and 0 < np.abs(left - right).mean() < 30
        assert off.ctx.error == "GL_NO_ERROR"
        app.close()


@pytest.mark.gl
def test_vr_long_trigger_sketches_and_touch_ball_highlights():
    from arboretum_client.app import App
    from arboretum_client.headless import OffscreenRenderer
    from arboretum_client.session_fake import FakeSession

    t = [0.0]
    with OffscreenRenderer((160, 120)) as off, off.ctx:
        app = App(off.renderer, FakeSession, out_dir=tempfile.mkdtemp(), clock=lambda: t[0], ui=False)
        app.start()
        rest = ctl(RIGHT, (2, 2, 0))
        n_hold = int(LONG_PRESS * 90) + 3
        script = [(ctl(LEFT, (0, 0, 0.2 + 0.01 * k), trigger=1.0), rest) for k in range(n_hold + 60)]
        script += [(ctl(LEFT, (0, 0, 0.9)), rest), (ctl(LEFT, (0, 0, 0.9), click=True), rest),
                   (ctl(LEFT, (0, 0, 0.9)), rest)]
        runtime = FakeRuntime(script)

        def tick_clock(orig=app.update):
            t[0] += 1 / 90
            return orig()
        app.update = tick_clock
        VrSession(app, runtime).run()
        assert app.worker.wait_idle(10)
        app.update()
        app.update()  # the new scene (with the sketch) is uploaded, then touched
        assert len(app.state.assembly.sketches) == 1  # one stroke -> a main branch, via the touchpad
        main = app.state.assembly.sketches[0].structure.branches[0].points
        assert main[0][2] < 0.3 and main[-1][2] > 0.7
        # the left touch ball now touches the sketched branch: its id is highlighted in blue
        assert app.touched[LEFT] is not None and app.touched[LEFT].endswith("branch:0")
        app.close()
