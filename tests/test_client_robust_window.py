"""A resized (maximised) client window draws at its new size and picks under the cursor (helper-52 bug 2).

The window part runs in a child process (this file run as a script) under Xvfb, like test_window.py:
the client starts at 400x300, the window is resized to 600x450 as a window manager would, then the
cursor is put on the window centre, where a placed example's main branch is drawn.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from test_window import xvfb_display  # noqa: F401  (the fixture: Xvfb on a free random display)

START, RESIZED = (400, 300), (600, 450)


def child() -> None:
    """Run ``arboretum client --offline`` in a window; print what the test checks as JSON."""
    import glfw
    import moderngl

    from arboretum_client import app as app_module
    from arboretum_client.camera import Camera
    from arboretum_library.cli import main

    apps, out, n = [], {}, {"poll": 0, "swap": 0}
    init = app_module.App.__init__

    def capture(self, *a, **k):
        init(self, *a, **k)
        apps.append(self)

    app_module.App.__init__ = capture
    poll, swap = glfw.poll_events, glfw.swap_buffers

    def on_poll():
        poll()
        n["poll"] += 1
        app, win = apps[0], glfw.get_current_context()
        if n["poll"] == 3:
            app.actions.add_example("oak-0001", np.eye(4))
        elif n["poll"] == 10:
            glfw.set_window_size(win, *RESIZED)
            for _ in range(5):
                poll()
        elif n["poll"] == 18:  # look at the trunk below the lobes, from the front, without panning
            trunk = app.state.examples["oak-0001"].structure.branches[0].points
            app.desktop.camera = Camera(target=tuple(trunk[1]), distance=0.6, azimuth=-90.0, elevation=0.0)
        elif n["poll"] == 20:  # the cursor to the window centre (picking uses the last frame drawn)
            ww, wh = glfw.get_window_size(win)
            cursor = glfw.set_cursor_pos_callback(win, None)  # the client's own callback
            glfw.set_cursor_pos_callback(win, cursor)
            cursor(win, ww / 2, wh / 2)
        elif n["poll"] == 30:
            out.update(touched=app.touched["right"], app_size=list(app.size),
                       renderer_size=list(app.renderer.size), window=list(glfw.get_window_size(win)))

    def on_swap(win):
        n["swap"] += 1
        if n["swap"] == 29:  # what the window shows: its default framebuffer
            ctx = moderngl.get_context()
            w, h = glfw.get_framebuffer_size(win)
            ctx.screen.use()
            img = np.frombuffer(ctx.screen.read(viewport=(0, 0, w, h), components=3), np.uint8).reshape(h, w, 3)
            out.update(framebuffer=[w, h], black=int((img.sum(axis=2) == 0).sum()),
                       centre=img[::-1][h // 2 - 1:h // 2 + 2, w // 2 - 1:w // 2 + 2].reshape(-1, 3).mean(0).tolist())
        swap(win)

    glfw.poll_events, glfw.swap_buffers = on_poll, on_swap
    rc = main(["client", "--offline", "--size", f"{START[0]}x{START[1]}", "--frames", "35", "--out", sys.argv[1]])
    print(json.dumps({**out, "rc": rc}))


@pytest.mark.gl
def test_a_resized_window_fills_and_picks_at_the_cursor(xvfb_display, tmp_path):  # noqa: F811
    env = {**os.environ, "DISPLAY": xvfb_display}
    done = subprocess.run([sys.executable, __file__, str(tmp_path)], env=env, capture_output=True, text=True,
                          timeout=120, cwd=os.path.dirname(__file__))
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["rc"] == 0 and got["window"] == list(RESIZED) and got["framebuffer"] == list(RESIZED)
    assert got["app_size"] == list(RESIZED) and got["renderer_size"] == list(RESIZED)
    assert got["black"] < 0.001 * RESIZED[0] * RESIZED[1]  # the frame fills the window (was 55 % black)
    assert got["touched"] is not None and got["touched"].endswith("/branch:0"), got["touched"]
    r, g, b = got["centre"]
    assert r > 120 and g < 100 and b < 100  # and the main branch (red) is what is drawn there


def test_cursor_positions_are_scaled_to_framebuffer_pixels_and_resizes_reach_the_app(monkeypatch):
    """A HiDPI window (framebuffer twice the window size): glfw reports the cursor in window units."""
    import glfw

    from arboretum_client.input.desktop import MouseMove
    from arboretum_client.window_input import install_callbacks

    callbacks = {}
    for name in ("cursor_pos", "mouse_button", "scroll", "key", "framebuffer_size"):
        monkeypatch.setattr(glfw, f"set_{name}_callback", lambda _w, cb, name=name: callbacks.__setitem__(name, cb))
    monkeypatch.setattr(glfw, "get_window_size", lambda _w: (640, 360))
    monkeypatch.setattr(glfw, "get_framebuffer_size", lambda _w: (1280, 720))

    class Fake:
        def __init__(self):
            self.events, self.sizes = [], []

        def handle(self, event):
            self.events.append(event)

        def resize(self, size):
            self.sizes.append(size)

    app = Fake()
    install_callbacks("win", app)
    callbacks["cursor_pos"]("win", 100.0, 50.5)
    assert app.events == [MouseMove(200.0, 101.0)]
    callbacks["framebuffer_size"]("win", 1280, 720)
    callbacks["framebuffer_size"]("win", 0, 0)  # minimised: keep the last size
    assert app.sizes == [(1280, 720)]


@pytest.mark.gl
def test_app_resize_renders_the_scene_and_ui_at_the_new_size():
    from arboretum_client.app import App
    from arboretum_client.headless import OffscreenRenderer
    from arboretum_client.scripts import ScriptRunner
    from arboretum_client.session_fake import FakeSession

    with OffscreenRenderer((320, 240)) as off, off.ctx:
        holder: list = []
        app = App(off.renderer, FakeSession, clock=lambda: holder[0].clock())
        runner = ScriptRunner(app)
        holder.append(runner)
        try:
            app.start()
            runner.settle()
            app.resize((500, 300))
            runner.tick(2)
            img = app.renderer.read()
            assert img.shape == (300, 500, 4) and app.desktop.size == (500, 300)
            assert app.canvas is not None and app.canvas.size == (500, 300)
            assert img[-5, 5, :3].max() < 80  # the status bar at the new bottom-left
            assert app.renderer.render_ids().shape == (300, 500)
        finally:
            app.close()


if __name__ == "__main__":
    child()
