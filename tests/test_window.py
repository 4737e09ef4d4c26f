"""A real glfw window under Xvfb renders the same pixels as headless EGL.

The window side runs in a child process (this file run as a script) so glfw's global state and the
window's GL context never mix with the EGL context of the test process.
"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

SIZE = (256, 192)


def scene_and_camera():
    """A small HBL: red main branch, black secondary, a translucent lobe, leaf points, a grid."""
    from arboretum_client.camera import fit_camera
    from arboretum_client.render.meshes import uv_sphere
    from arboretum_client.scene_build import HBLStyle, hbl_scene
    from arboretum_library.model import HBL, Branch, Level, Lobe

    v, f = uv_sphere(8, 12)
    main = Branch(points=np.c_[np.zeros(5), np.zeros(5), np.linspace(0, 1, 5)], radii=np.linspace(0.03, 0.01, 5))
    sec = Branch(points=[[0, 0, 0.5], [0.3, 0.1, 0.7]], radii=[0.01, 0.006], parent=0, parent_vertex=2,
                 level=Level.SECONDARY)
    lobe = Lobe(points=np.zeros((0, 3)), hull_vertices=v * 0.2 + [0.45, 0.1, 0.8], hull_faces=f,
                centre=[0.45, 0.1, 0.8], branch=1)
    pts = np.random.default_rng(7).normal(size=(200, 3)) * 0.07 + [0.45, 0.1, 0.8]
    hbl = HBL(root=[0, 0, 0], branches=(main, sec), lobes=(lobe,), points=pts, labels=np.ones(200, np.uint8))
    scene = hbl_scene(hbl, HBLStyle(show_points=True))
    return scene, fit_camera(scene.bounds(), "iso", SIZE[0] / SIZE[1])


def child(out: str) -> None:
    """Open a window on $DISPLAY, render, save [offscreen image, window framebuffer] to ``out``."""
    from arboretum_client.context import open_window
    from arboretum_client.render.renderer import Renderer

    scene, cam = scene_and_camera()
    win = open_window(SIZE, "arboretum test", visible=True)
    ctx = win.ctx
    r = Renderer(ctx, SIZE)
    r.upload(scene)
    r.render(cam)
    image = r.read()
    ctx.copy_framebuffer(ctx.screen, r.framebuffer)  # what a frame loop shows
    # moderngl's screen.read() selects GL_COLOR_ATTACHMENT0, invalid on a window's default framebuffer:
    # copy the window's back buffer into a plain framebuffer and read that instead.
    back = ctx.simple_framebuffer(SIZE)
    ctx.copy_framebuffer(back, ctx.screen)
    screen = np.frombuffer(back.read(components=4), np.uint8).reshape(SIZE[1], SIZE[0], 4)[::-1]
    back.release()
    error = ctx.error
    win.swap()
    r.release()
    win.close()
    if error != "GL_NO_ERROR":
        raise SystemExit(f"GL error in the window: {error}")
    np.save(out, np.stack([image, screen]))


@pytest.fixture
def xvfb_display():
    """Start Xvfb on a free random display number; yield ':N'; stop it."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb)")
    rng = random.Random()
    for _ in range(20):
        n = rng.randrange(100, 1000)
        if not Path(f"/tmp/.X{n}-lock").exists() and not Path(f"/tmp/.X11-unix/X{n}").exists():
            break
    proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 15
    while not Path(f"/tmp/.X11-unix/X{n}").exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"Xvfb :{n} did not start")
        time.sleep(0.05)
    yield f":{n}"
    proc.terminate()
    proc.wait(timeout=10)


@pytest.mark.gl
def test_glfw_window_under_xvfb_matches_the_egl_render(xvfb_display, tmp_path):
    from arboretum_client.headless import OffscreenRenderer

    out = tmp_path / "window.npy"
    env = {**os.environ, "DISPLAY": xvfb_display}
    done = subprocess.run([sys.executable, __file__, str(out)], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    image, screen = np.load(out).astype(int)
    scene, cam = scene_and_camera()
    with OffscreenRenderer(SIZE) as r:
        egl = r.render(scene, cam).astype(int)
        assert r.ctx.error == "GL_NO_ERROR"
    assert (np.abs(egl - image) > 0).mean() < 0.01 and np.abs(egl - image).max() <= 24
    assert np.abs(image[..., :3] - screen[..., :3]).max() == 0  # the blit to the window is exact
    red = (egl[..., 0] > 150) & (egl[..., 1] < 90)
    assert red.sum() > 50  # the scene is really there (main branch)


def test_open_window_without_display_is_a_clear_error(monkeypatch):
    from arboretum_client.context import ContextError, open_window

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ContextError, match="DISPLAY is not set"):
        open_window((64, 64))


if __name__ == "__main__":
    child(sys.argv[1])
