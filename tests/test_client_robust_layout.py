"""The UI lays out at every size --size accepts (helper-52 bug 4) and 16-bit references keep their
grey levels (bug 5)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from arboretum_client.net import JobStatus
from arboretum_client.tools.state import REFINEMENT, ClientState
from arboretum_client.ui.layout import draw_ui

SIZES = [(16, 16), (16, 8192), (100, 60), (200, 150), (239, 400), (240, 100), (300, 200), (480, 270),
         (640, 360), (2000, 40)]


def _busy_state(mode: str = "modeling") -> tuple[ClientState, dict[int, JobStatus]]:
    s = ClientState()
    s.mode = mode
    s.library = [{"id": f"oak-{i:04d}", "lobe_count": 3, "tags": ["dense"]} for i in range(20)]
    s.say("a status message long enough to need cutting on a narrow window " * 3)
    jobs = {1: JobStatus("grow", 0.4, "growing twigs"), 2: JobStatus("export", None), 3: JobStatus("sync", 1.0)}
    return s, jobs


@pytest.mark.parametrize("mode", ["modeling", REFINEMENT])
@pytest.mark.parametrize("size", SIZES)
def test_the_ui_draws_at_small_and_odd_sizes_with_jobs_running(size, mode):
    state, jobs = _busy_state(mode)
    canvas = draw_ui(size, state, jobs)
    img = canvas.rgba()
    assert img.shape == (size[1], size[0], 4)
    assert img[-1, 0, 3] > 0  # the status bar is there, bottom-left
    for (x0, y0, x1, y1), _action in canvas.regions:
        assert x0 <= x1 and y0 <= y1


def test_the_library_list_fits_above_the_status_bar_at_640x360():
    state, _ = _busy_state()
    canvas = draw_ui((640, 360), state, {})
    rows = [box for box, action in canvas.regions if action.startswith("choose:")]
    tools = [box for box, action in canvas.regions if action in ("save", "load", "mode")]
    assert 0 < len(rows) < 12 and len(tools) == 3
    assert max(box[3] for box in tools) <= 360 - 26  # the last button row ends above the status bar


def test_a_narrow_output_drops_the_panel_and_keeps_the_message():
    state, jobs = _busy_state()
    canvas = draw_ui((120, 300), state, jobs)
    assert canvas.regions == []  # no side panel narrower than MIN_PANEL
    assert canvas.rgba()[:200, :, 3].max() == 0


@pytest.mark.gl
@pytest.mark.parametrize("size", ["16x16", "200x150", "239x400"])
def test_cli_runs_a_grow_at_small_sizes(tmp_path, size):
    script = tmp_path / "s.json"
    script.write_text(json.dumps([{"action": "choose:oak-0001"}, {"action": "grow"}, {"wait": 0.1},
                                  {"screenshot": "s.png"}]))
    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--offline", "--headless", "--script",
           str(script), "--size", size, "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    from PIL import Image

    w, h = (int(v) for v in size.split("x"))
    assert Image.open(tmp_path / "s.png").size == (w, h)
    assert json.loads(done.stdout)["errors"] == ["grow: grow: the assembly is empty; add an example first"]


def test_a_16_bit_grayscale_reference_keeps_its_grey_levels(tmp_path):
    from PIL import Image

    from arboretum_client.app import load_reference

    ramp = np.tile(np.array([0, 257 * 64, 257 * 128, 65535], np.uint16), (3, 1))
    Image.fromarray(ramp).save(tmp_path / "g16.png")
    assert Image.open(tmp_path / "g16.png").mode.startswith("I")
    rgba = load_reference(tmp_path / "g16.png")
    assert rgba.dtype == np.uint8 and rgba.shape == (3, 4, 4)
    assert rgba[0, :, 0].tolist() == [0, 64, 128, 255]
    assert np.array_equal(rgba[..., 0], rgba[..., 1]) and np.array_equal(rgba[..., 0], rgba[..., 2])
    assert (rgba[..., 3] == 255).all()


def test_8_bit_references_are_unchanged(tmp_path):
    from PIL import Image

    from arboretum_client.app import load_reference

    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3) * 10
    Image.fromarray(rgb).save(tmp_path / "c.png")
    Image.fromarray(rgb[..., 0]).save(tmp_path / "l.png")
    assert np.array_equal(load_reference(tmp_path / "c.png")[..., :3], rgb)
    assert np.array_equal(load_reference(tmp_path / "l.png")[..., 0], rgb[..., 0])
