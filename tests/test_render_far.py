"""``arboretum render`` of georeferenced data (UTM-like coordinates): drawn relative to the scene's centre,
taken in float64 before the GPU's float32, so a shifted scan looks like the same scan at the origin."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from arboretum_client.scene_build import far_origin, hbl_scene, mesh_scene, points_scene
from arboretum_library.assets import assets_dir
from arboretum_library.cli import main
from arboretum_library.export.gltf import write_glb
from arboretum_library.export.obj import write_obj
from arboretum_library.export.parts import Material, MeshPart
from arboretum_library.model import HBL, Branch

UTM = np.array([512345.0, 4123456.0, 312.0])
COFFEE = assets_dir() / "scans" / "01_rtwig_coffeetree" / "01_rtwig_coffeetree.xyz"


def foreground(png) -> int:
    """Pixels that differ from the background gradient (estimated per row from the image's side columns)."""
    im = np.asarray(Image.open(png).convert("RGB")).astype(int)
    bg = (im[:, :3].mean(axis=1) + im[:, -3:].mean(axis=1)) / 2
    return int((np.abs(im - bg[:, None, :]).sum(axis=2) > 30).sum())


def _render(inputs, out, *extra) -> int:
    assert main(["render", *map(str, inputs), "--out", str(out), "--size", "320x240", "--no-grid", *extra]) == 0
    return foreground(out)


def test_far_origin_only_moves_far_scenes():
    np.testing.assert_array_equal(far_origin(np.array([[0, 0, 0], [10, 20, 30.0]])), 0)
    np.testing.assert_array_equal(far_origin(np.array([[0, 0, 0], [2, 2, 2.0]]) + UTM), UTM + 1)
    np.testing.assert_array_equal(far_origin(np.zeros((0, 3))), 0)


def test_builders_subtract_the_origin_in_float64(rng):
    pts = rng.normal(size=(100, 3)) + UTM
    local = points_scene(pts, grid=False, origin=UTM).items[0].points
    assert local.dtype == np.float32 and np.abs(local - (pts - UTM)).max() < 1e-5
    tri = mesh_scene(pts[:3], np.array([[0, 1, 2]]), grid=False, origin=UTM).items[0].vertices
    assert np.abs(tri - (pts[:3] - UTM)).max() < 1e-5
    hbl = HBL(root=UTM, branches=(Branch(points=UTM + [[0, 0, 0], [0, 0, 1.0]], radii=[0.1, 0.05]),))
    line = hbl_scene(hbl, origin=UTM).items[0].points
    np.testing.assert_allclose(line, [[0, 0, 0], [0, 0, 1]], atol=1e-6)


def test_shifted_scan_renders_like_the_scan_at_the_origin(tmp_path):
    p = np.loadtxt(COFFEE)[:, :3]
    np.savetxt(tmp_path / "utm.xyz", p + UTM, fmt="%.4f")
    at_origin = _render([COFFEE], tmp_path / "ref.png")
    shifted = _render([tmp_path / "utm.xyz"], tmp_path / "utm.png")
    assert at_origin > 1500
    assert shifted == pytest.approx(at_origin, rel=0.03)


def _spheres(offset) -> list[MeshPart]:
    s = trimesh.creation.icosphere(3, radius=1.0)
    return [MeshPart("a", s.vertices + [0, 0, 2] + offset, s.faces),
            MeshPart("b", s.vertices * 0.5 + [2.5, 0, 1] + offset, s.faces)]


def test_shifted_meshes_in_two_objs_render_like_at_the_origin(tmp_path):
    for name, offset in (("near", np.zeros(3)), ("far", UTM)):
        for part in _spheres(offset):
            write_obj(tmp_path / f"{name}_{part.name}.obj", [part], [Material("m")])
    ref = _render([tmp_path / "near_a.obj", tmp_path / "near_b.obj"], tmp_path / "near.png", "--view", "front")
    far = _render([tmp_path / "far_a.obj", tmp_path / "far_b.obj"], tmp_path / "far.png", "--view", "front")
    assert ref > 3000
    assert far == pytest.approx(ref, rel=0.03)


def test_shifted_glb_renders_like_at_the_origin(tmp_path):
    write_glb(tmp_path / "near.glb", _spheres(np.zeros(3)), [Material("m")])
    write_glb(tmp_path / "far.glb", _spheres(UTM), [Material("m")])
    ref = _render([tmp_path / "near.glb"], tmp_path / "near.png", "--view", "front")
    far = _render([tmp_path / "far.glb"], tmp_path / "far.png", "--view", "front")
    assert ref > 3000
    assert far == pytest.approx(ref, rel=0.03)
