"""Under Xvfb a real glfw window opens, runs the client's frames (scripted input), renders and closes."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from test_window import xvfb_display  # noqa: F401  (the fixture: Xvfb on a free random display)

SCRIPT = {"steps": [{"action": "choose:oak-0001"}, {"world": [0, 0, 0]}, {"click": "left"},
                    {"view": "front"}, {"mouse": [700, 20]}]}


@pytest.mark.gl
def test_client_window_opens_renders_and_closes(xvfb_display, tmp_path):  # noqa: F811
    script = tmp_path / "s.json"
    script.write_text(json.dumps(SCRIPT))
    shot = tmp_path / "window.png"
    env = {**os.environ, "DISPLAY": xvfb_display}
    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--offline", "--script", str(script),
           "--screenshot", str(shot), "--size", "800x450", "--out", str(tmp_path), "--json"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads(done.stdout)
    assert summary["placements"] == 1 and summary["errors"] == [] and summary["frames"] > 5
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert img.shape == (450, 800, 3)
    red = (img[..., 0] > 150) & (img[..., 1] < 90) & (img[..., 2] < 90)
    assert red[:, 270:].sum() > 100  # the main branch, right of the panel
    assert img[60:200, 20:240].mean() < 110  # the library panel


@pytest.mark.gl
def test_vr_flag_without_a_runtime_falls_back_to_the_desktop_window(xvfb_display, tmp_path):  # noqa: F811
    pytest.importorskip("xr")
    env = {**os.environ, "DISPLAY": xvfb_display}
    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--offline", "--vr", "--frames", "3",
           "--size", "320x200", "--out", str(tmp_path), "--json"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "no OpenXR runtime" in done.stderr and "using the desktop" in done.stderr
    assert json.loads(done.stdout)["frames"] == 3
