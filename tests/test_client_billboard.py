"""Reference-image billboards: textured world quads drawn with alpha blending, the texture cached,
and ``arboretum client --reference`` showing one (EGL, headless)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from arboretum_client.app import load_reference, reference_billboard
from arboretum_client.camera import Camera
from arboretum_client.headless import OffscreenRenderer
from arboretum_client.render.renderer import BACKGROUND_BOTTOM, BACKGROUND_TOP
from arboretum_client.scene import Billboard, Scene
from arboretum_library.errors import InputError, ValidationError

SIZE = (160, 120)
MAGENTA = (255, 0, 255, 255)


def solid(h: int, w: int, rgba=MAGENTA) -> np.ndarray:
    img = np.zeros((h, w, 4), np.uint8)
    img[...] = rgba
    return img


def magenta_mask(img: np.ndarray) -> np.ndarray:
    return (img[..., 0] > 235) & (img[..., 1] < 25) & (img[..., 2] > 235)


def projected_box(cam: Camera, bb: Billboard, size=SIZE) -> tuple[np.ndarray, np.ndarray]:
    px = cam.project(bb.corners(cam.eye), size)
    return px.min(axis=0), px.max(axis=0)


@pytest.fixture(scope="module")
def off():
    with OffscreenRenderer(SIZE) as r:
        yield r
        assert r.ctx.error == "GL_NO_ERROR"


def test_magenta_pixels_fill_the_projected_quad_and_nothing_else(off):
    bb = Billboard(solid(8, 16), (0.0, 0.0, 0.5), 1.0, 0.5)
    cam = Camera(target=(0.0, 0.0, 0.5), distance=4.0)
    img = off.render(Scene(items=(bb,)), cam)
    lo, hi = projected_box(cam, bb)
    m = magenta_mask(img)
    ys, xs = np.nonzero(m)
    assert m.sum() > 300
    assert xs.min() >= lo[0] - 1.5 and xs.max() <= hi[0] + 1.5
    assert ys.min() >= lo[1] - 1.5 and ys.max() <= hi[1] + 1.5
    cx, cy = ((lo + hi) / 2).astype(int)
    assert m[cy, cx] and m[cy, cx - 10] and m[cy - 5, cx + 10]
    assert not m[:, : int(lo[0]) - 2].any() and not m[:, int(hi[0]) + 3:].any()
    assert off.renderer.stats.draw_calls == 2  # background + one billboard


def test_transparent_left_half_shows_the_background(off):
    image = solid(8, 16)
    image[:, :8, 3] = 0
    bb = Billboard(image, (0.0, 0.0, 0.5), 1.0, 0.5)
    cam = Camera(target=(0.0, 0.0, 0.5), distance=3.0, azimuth=-90.0, elevation=0.0)
    img = off.render(Scene(items=(bb,)), cam)
    lo, hi = projected_box(cam, bb)
    cy = int((lo[1] + hi[1]) / 2)
    left_x, right_x = int(lo[0] + 0.25 * (hi[0] - lo[0])), int(lo[0] + 0.75 * (hi[0] - lo[0]))
    assert magenta_mask(img)[cy, right_x]
    assert not magenta_mask(img)[:, : int((lo[0] + hi[0]) / 2) - 2].any()
    grey = np.array([BACKGROUND_BOTTOM, BACKGROUND_TOP]) * 255
    px = img[cy, left_x, :3].astype(float)
    assert np.all(px >= grey.min(axis=0) - 3) and np.all(px <= grey.max(axis=0) + 3)


def test_the_texture_is_uploaded_once_across_frames_and_uploads(off):
    bb = Billboard(solid(4, 4), (0.0, 0.0, 0.5), 1.0, 1.0)
    cam = Camera(target=(0.0, 0.0, 0.5), distance=4.0)
    before = off.renderer.texture_uploads
    off.render(Scene(items=(bb,)), cam)
    off.render(Scene(items=(bb,)), cam)   # a re-upload of a scene holding the same billboard
    for _ in range(3):
        off.renderer.render(cam)
    assert off.renderer.texture_uploads - before == 1
    assert len(off.renderer._textures) == 1
    other = Billboard(solid(4, 4, (0, 255, 0, 255)), (0.0, 0.0, 0.5), 1.0, 1.0)
    off.render(Scene(items=(other,)), cam)
    assert off.renderer.texture_uploads - before == 2
    assert len(off.renderer._textures) == 1  # the unused one was freed


def test_billboards_are_not_pickable(off):
    bb = Billboard(solid(8, 8), (0.0, 0.0, 0.5), 1.0, 1.0, pick_id=7)
    cam = Camera(target=(0.0, 0.0, 0.5), distance=4.0)
    img = off.render(Scene(items=(bb,)), cam)
    assert magenta_mask(img)[SIZE[1] // 2, SIZE[0] // 2]
    assert off.pick(SIZE[0] // 2, SIZE[1] // 2) is None


def test_a_camera_facing_billboard_turns_to_the_eye_and_a_fixed_one_does_not():
    facing = Billboard(solid(2, 2), (0.0, 0.0, 0.0), 2.0, 1.0, normal=None)
    fixed = Billboard(solid(2, 2), (0.0, 0.0, 0.0), 2.0, 1.0)
    r, u = facing.axes(np.array([5.0, 0.0, 1.0]))
    np.testing.assert_allclose(r, [0.0, 1.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(u, [0.0, 0.0, 0.5], atol=1e-9)
    r, u = fixed.axes(np.array([5.0, 0.0, 1.0]))
    np.testing.assert_allclose(r, [1.0, 0.0, 0.0], atol=1e-9)
    with pytest.raises(ValidationError):
        Billboard(solid(2, 2), (0.0, 0.0, 0.0), 0.0, 1.0)


def test_reference_billboard_stands_behind_the_origin_with_the_image_aspect(tmp_path):
    path = tmp_path / "r.png"
    Image.fromarray(solid(200, 100)).save(path)
    bb = reference_billboard(load_reference(path), 1.2)
    assert (bb.height, bb.width) == (1.2, pytest.approx(0.6))
    np.testing.assert_allclose(bb.corners()[:, 2].min(), 0.0, atol=1e-6)
    assert bb.center[1] > 0
    with pytest.raises(InputError, match="no such file"):
        load_reference(tmp_path / "missing.png")
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(InputError, match="cannot read"):
        load_reference(tmp_path / "bad.png")


def _client(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "arboretum_library.cli", "client", "--offline", "--headless",
                           "--size", "800x600", "--out", str(tmp_path), *extra],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)


def test_cli_reference_shows_in_the_screenshot_and_toggles_off(tmp_path):
    Image.fromarray(solid(60, 40)).save(tmp_path / "img.png")
    (tmp_path / "s.json").write_text(json.dumps({"steps": [{"wait": 0.1}]}))
    (tmp_path / "off.json").write_text(json.dumps({"steps": [{"action": "reference"}]}))
    res = _client(tmp_path, "--script", "s.json", "--reference", "img.png", "--screenshot", "on.png")
    assert res.returncode == 0, res.stderr
    assert magenta_mask(np.asarray(Image.open(tmp_path / "on.png").convert("RGBA"))).sum() > 200
    res = _client(tmp_path, "--script", "off.json", "--reference", "img.png", "--screenshot", "off.png")
    assert res.returncode == 0, res.stderr
    assert magenta_mask(np.asarray(Image.open(tmp_path / "off.png").convert("RGBA"))).sum() == 0


def test_script_key_reference_and_a_bad_image_is_one_clear_error(tmp_path):
    Image.fromarray(solid(60, 40)).save(tmp_path / "img.png")
    (tmp_path / "s.json").write_text(json.dumps({"reference": "img.png", "steps": [{"wait": 0.1}]}))
    res = _client(tmp_path, "--script", "s.json", "--screenshot", "shot.png")
    assert res.returncode == 0, res.stderr
    assert magenta_mask(np.asarray(Image.open(tmp_path / "shot.png").convert("RGBA"))).sum() > 200
    res = _client(tmp_path, "--script", "s.json", "--reference", "nope.png")
    assert res.returncode == 2 and "nope.png" in res.stderr and "Traceback" not in res.stderr
