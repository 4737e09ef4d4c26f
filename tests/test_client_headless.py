"""The client headless (EGL): scripted input on the same code path, screenshots checked by content, and
a golden image (llvmpipe only, with a tolerance)."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from arboretum_client.app import App
from arboretum_client.headless import OffscreenRenderer, save_png
from arboretum_client.scene_build import LOBE_PALETTE
from arboretum_client.scripts import ScriptRunner
from arboretum_client.session_fake import FakeSession
from arboretum_library.errors import InputError

GOLDEN = Path(__file__).parent / "golden"
SIZE = (400, 300)


@pytest.fixture
def client():
    """(app, runner) on an EGL renderer with the FakeSession; ``ui`` off so content checks see the scene."""
    made = []

    def make(ui=False, size=SIZE):
        off = OffscreenRenderer(size)
        off.ctx.__enter__()
        holder = []
        app = App(off.renderer, FakeSession, out_dir=tempfile.mkdtemp(), clock=lambda: holder[0].clock(), ui=ui)
        runner = ScriptRunner(app)
        holder.append(runner)
        app.start()
        runner.settle()
        made.append((off, app))
        return app, runner

    yield make
    for off, app in made:
        assert off.ctx.error == "GL_NO_ERROR"
        app.close()
        off.ctx.__exit__(None, None, None)
        off.close()


def place(runner, example, xyz):
    runner.run([{"action": f"choose:{example}"}, {"world": list(xyz)}, {"click": "left"}])


def test_a_placed_example_draws_lobes_in_their_colours_and_the_main_branch_red(client):
    app, runner = client()
    place(runner, "oak-0001", (0, 0, 0))
    runner.run([{"view": "front"}, {"mouse": [2, 2]}])
    img = app.renderer.read()[..., :3].astype(int)
    cam = app.desktop.camera
    p = app.state.assembly.placements[0]
    hbl = app.state.examples[p.example_id].structure
    for j, lobe in enumerate(hbl.lobes):
        x, y = cam.project(lobe.centre[None], SIZE)[0].astype(int)
        colour = np.array(LOBE_PALETTE[j]) * 255
        patch = img[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3).mean(axis=0)
        bg = np.array([236, 238, 242])
        # translucent: the lobe pulls the background towards its own colour
        assert np.dot(patch - bg, colour - bg) > 0, (j, patch, colour)
    main = hbl.branches[0].points[1:-1]
    px = cam.project(main, SIZE).astype(int)
    reds = [(img[y, x, 0] > 120) & (img[y, x, 1] < 90) & (img[y, x, 2] < 90) for x, y in px]
    assert np.mean(reds) >= 0.7


def test_the_touched_item_is_highlighted_in_the_hand_colour(client):
    app, runner = client()
    place(runner, "oak-0001", (0, 0, 0))
    runner.run([{"view": "front"}, {"mouse": [2, 2]}])
    lobe = app.state.examples["oak-0001"].structure.lobes[0]
    x, y = app.desktop.camera.project(lobe.centre[None], SIZE)[0]
    plain = app.renderer.read()[int(y), int(x), :3].astype(int)
    runner.run([{"mouse": [float(x), float(y)]}])
    assert app.touched["right"] == "inst:oak-0001#1/lobe:0"
    lit = app.renderer.read()[int(y), int(x), :3].astype(int)
    assert lit[0] - plain[0] > 40 and lit[0] > lit[2]  # pulled towards the right hand's red
    runner.run([{"mouse": [2, 2]}, {"hold": "ctrl"}, {"mouse": [float(x), float(y)]}])
    blue = app.renderer.read()[int(y), int(x), :3].astype(int)
    assert app.touched["right"] is None and app.touched["left"] == "inst:oak-0001#1/lobe:0"
    assert blue[2] - plain[2] > 40 and blue[2] > blue[0]  # the left hand's blue


def test_panels_and_status_bar_are_drawn_and_clickable(client):
    app, runner = client(ui=True, size=(800, 500))
    img = app.renderer.read()[..., :3].astype(int)
    assert img[40:200, 20:240].mean() < 110  # the dark library panel
    assert img[495, 400].mean() < 80  # status bar
    region = next(box for box, action in app.canvas.regions if action == "choose:pine-0002")
    runner.run([{"mouse": [(region[0] + region[2]) / 2, (region[1] + region[3]) / 2]}, {"click": "left"}])
    assert app.state.chosen == "pine-0002" and app.state.assembly.placements == ()  # no click reached the scene


def test_search_typed_in_the_panel(client):
    app, runner = client(ui=True, size=(800, 500))
    runner.run([{"key": "/"}, {"key": "p"}, {"key": "i"}, {"key": "n"}, {"key": "enter"}])
    assert app.state.query == "pin" and not app.state.search_focus
    assert sorted(r["id"] for r in app.state.library) == ["pine-0001", "pine-0002", "pine-0003"]
    assert app.state.show_points  # 'p' went into the search box, not to the show-points shortcut


def test_scripted_stroke_sketches_an_example_through_the_mouse(client):
    app, runner = client()
    place(runner, "oak-0001", (0, 0, 0))
    runner.run([{"view": "front"}, {"mouse": [2, 2]}])
    runner.run([{"stroke": [[0.8, -0.5, 0.0], [0.8, -0.5, 0.4], [0.8, -0.5, 0.8], [0.85, -0.5, 1.2]]},
                {"key": "enter"}])
    assert len(app.state.assembly.sketches) == 1 and "branch" in app.state.status


def check_golden(app, name: str) -> None:
    """Compare the last frame with tests/golden/NAME (llvmpipe only; ARBORETUM_REGEN_GOLDEN=1 rewrites it)."""
    image = app.renderer.read()[..., :3]
    gold = GOLDEN / name
    renderer = app.renderer.ctx.info.get("GL_RENDERER", "")
    if os.environ.get("ARBORETUM_REGEN_GOLDEN"):
        save_png(image, gold)
    if "llvmpipe" not in renderer:
        pytest.skip(f"golden images are for Mesa llvmpipe, not {renderer}")
    from PIL import Image

    want = np.asarray(Image.open(gold).convert("RGB")).astype(int)
    diff = np.abs(want - image.astype(int))
    if not (diff.mean() <= 1.0 and (diff.max(axis=2) > 40).mean() < 0.005):
        out = Path(tempfile.mkdtemp(prefix="golden-"))
        save_png(image, out / "actual.png")
        save_png(np.clip(diff * 4, 0, 255).astype(np.uint8), out / "diff.png")
        pytest.fail(f"client image differs from {gold.name}: mean {diff.mean():.2f}; see {out}")


def test_golden_client_modeling(client):
    app, runner = client(size=(320, 240))
    place(runner, "oak-0002", (0, 0, 0))
    place(runner, "pine-0003", (0.9, 0.5, 0))
    runner.run([{"action": "grow"}, {"view": "iso"}, {"mouse": [1, 1]}, {"wait": 3.0}])
    check_golden(app, "client_modeling_iso.png")


def test_golden_client_refinement(client):
    app, runner = client(size=(320, 240))
    runner.run([{"key": "tab"}, {"select": ["lobe:1", "lobe:4"]}, {"view": "front"}, {"mouse": [1, 1]}])
    assert app.state.mode == "refinement" and len(app.state.draft.lobes) == 9
    check_golden(app, "client_refinement_front.png")


def test_a_bad_script_is_one_clear_error(tmp_path, client):
    from arboretum_client.scripts import load_script

    bad = tmp_path / "s.json"
    bad.write_text(json.dumps({"steps": [{"teleport": 1}]}))
    app, runner = client()
    with pytest.raises(InputError, match="unknown step 'teleport'"):
        runner.run(load_script(bad)["steps"])
    (tmp_path / "t.json").write_text("{not json")
    with pytest.raises(InputError, match="not valid json"):
        load_script(tmp_path / "t.json")
