"""Textured meshes in the renderer (headless EGL): texture orientation, alpha cut-outs and picking,
instancing, the texture cache, cut-out-aware mipmaps, and ``arboretum render`` on a grown tree's GLB."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from arboretum_client.camera import Camera
from arboretum_client.headless import OffscreenRenderer
from arboretum_client.render.meshes import quad
from arboretum_client.render.textures import coverage_mipmaps, mip_sizes
from arboretum_client.render_cli import run as render_run
from arboretum_client.scene import InstancedMesh, Mesh, Scene
from arboretum_library.errors import ValidationError
from factories import make_hbl

SIZE = (160, 120)
RED, GREEN, BLUE, YELLOW = (255, 0, 0, 255), (0, 255, 0, 255), (0, 0, 255, 255), (255, 255, 0, 255)
FRONT = Camera(target=(0.0, 0.0, 0.5), distance=2.2, azimuth=-90.0, elevation=0.0)
"""Looks along +Y at the unit quad (x -0.5..0.5, z 0..1, facing -Y)."""
BEHIND = dataclasses.replace(FRONT, azimuth=90.0)
QUAD_UV = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], np.float32)
"""glTF UVs of ``quad()``'s corners: bottom-left, bottom-right, top-right, top-left (v = 0 at the top)."""


def checker() -> np.ndarray:
    """2 x 2 RGBA: top row red, green; bottom row blue, yellow."""
    img = np.array([[RED, GREEN], [BLUE, YELLOW]], np.uint8)
    img.flags.writeable = False
    return img


def leaf_like(h: int = 16, w: int = 16) -> np.ndarray:
    """Left half transparent (its colour magenta, so any bleed would show), right half opaque green."""
    img = np.zeros((h, w, 4), np.uint8)
    img[:, : w // 2] = (255, 0, 255, 0)
    img[:, w // 2:] = (40, 200, 40, 255)
    return img


def quad_mesh(texture, pick_id=1, offset=(0.0, 0.0, 0.0), **kw) -> Mesh:
    v, f = quad()
    return Mesh((v + offset).astype(np.float32), f.astype(np.int32), (1.0, 1.0, 1.0, 1.0), pick_id,
                uv=QUAD_UV, texture=texture, **kw)


def at(cam: Camera, point, size=SIZE) -> tuple[int, int]:
    """Output pixel (x, y) of a world point."""
    x, y = cam.project(np.asarray(point, float)[None], size)[0]
    return int(x), int(y)


def dominant(rgb) -> str:
    """'r', 'g', 'b' or 'y' (red and green both strong) for a lit pixel."""
    r, g, b = (float(c) for c in rgb[:3])
    if r > 2 * b and g > 2 * b and min(r, g) > 0.6 * max(r, g):
        return "y"
    return "rgb"[int(np.argmax([r, g, b]))] if max(r, g, b) > 2.5 * sorted([r, g, b])[1] else "?"


@pytest.fixture(scope="module")
def off():
    with OffscreenRenderer(SIZE) as r:
        yield r
        assert r.ctx.error == "GL_NO_ERROR"


def test_checker_texels_land_in_their_quadrants_with_v_zero_at_the_top(off):
    img = off.render(Scene(items=(quad_mesh(checker()),)), FRONT)
    quadrants = {"r": (-0.25, 0.0, 0.75), "g": (0.25, 0.0, 0.75), "b": (-0.25, 0.0, 0.25), "y": (0.25, 0.0, 0.25)}
    for want, point in quadrants.items():
        x, y = at(FRONT, point)
        assert dominant(img[y, x]) == want, (want, img[y, x])
    top_left = img[at(FRONT, (-0.25, 0.0, 0.75))[1], at(FRONT, (-0.25, 0.0, 0.75))[0]]
    assert top_left[0] > 150 and top_left[0] > 3 * max(top_left[1], top_left[2])  # lit red: texture times white


def test_cut_out_half_shows_the_background_and_is_not_pickable(off):
    empty = off.render(Scene(), FRONT)
    leaf = quad_mesh(leaf_like(), pick_id=5)
    img = off.render(Scene(items=(leaf,)), FRONT)
    xl, yl = at(FRONT, (-0.25, 0.0, 0.5))
    xr, yr = at(FRONT, (0.25, 0.0, 0.5))
    np.testing.assert_array_equal(img[yl, xl], empty[yl, xl])
    assert img[yr, xr, 1] > 120 and img[yr, xr, 1] > 2 * img[yr, xr, 0]  # the opaque half: green
    assert not ((img[..., 0] > 150) & (img[..., 2] > 150) & (img[..., 1] < 100)).any()
    assert off.pick(xl, yl) is None
    assert off.pick(xr, yr) == 5
    behind = Mesh(np.array([[-1, 0.5, -1], [1, 0.5, -1], [1, 0.5, 2], [-1, 0.5, 2]], np.float32),
                  np.array([[0, 1, 2], [0, 2, 3]], np.int32), (0.2, 0.2, 0.9), 9)
    off.render(Scene(items=(leaf, behind)), FRONT)
    assert off.pick(xl, yl) == 9 and off.pick(xr, yr) == 5  # picked through the cut-out


def test_single_sided_textured_mesh_is_culled_from_behind(off):
    empty_back = off.render(Scene(), BEHIND)
    x, y = at(BEHIND, (0.25, 0.0, 0.75))
    two = off.render(Scene(items=(quad_mesh(checker()),)), BEHIND)
    assert dominant(two[y, x]) == "g"  # seen from behind: the same texel at the same world point
    one = off.render(Scene(items=(quad_mesh(checker(), double_sided=False),)), BEHIND)
    np.testing.assert_array_equal(one[y, x], empty_back[y, x])
    assert off.pick(x, y) is None
    front = off.render(Scene(items=(quad_mesh(checker(), double_sided=False),)), FRONT)
    assert dominant(front[at(FRONT, (-0.25, 0.0, 0.75))[1], at(FRONT, (-0.25, 0.0, 0.75))[0]]) == "r"


def test_every_instance_shows_the_texture(off):
    n = 4
    mats = np.tile(np.eye(4, dtype=np.float32), (n, 1, 1))
    mats[:, 0, 3] = (np.arange(n) - 1.5) * 1.2
    v, f = quad()
    mesh = Mesh(v.astype(np.float32), f.astype(np.int32), (1.0, 1.0, 1.0), 3, uv=QUAD_UV, texture=checker())
    cam = dataclasses.replace(FRONT, distance=6.0)
    img = off.render(Scene(items=(InstancedMesh(mesh, mats),)), cam)
    assert off.renderer.stats.draw_calls == 2  # background + one instanced call
    for x0 in mats[:, 0, 3]:
        for want, (dx, dz) in {"r": (-0.25, 0.75), "g": (0.25, 0.75), "b": (-0.25, 0.25), "y": (0.25, 0.25)}.items():
            x, y = at(cam, (x0 + dx, 0.0, dz))
            assert dominant(img[y, x]) == want, (x0, want, img[y, x])
        assert off.pick(*at(cam, (x0, 0.0, 0.5))) == 3


def test_each_texture_is_uploaded_once_across_meshes_frames_and_uploads(off):
    tex = checker()
    a = quad_mesh(tex, 1)
    b = quad_mesh(tex, 2, offset=(1.2, 0.0, 0.0))
    inst = InstancedMesh(quad_mesh(tex, 3), np.eye(4, dtype=np.float32)[None])
    scene = Scene(items=(a, b, inst))
    before = off.renderer.texture_uploads
    off.render(scene, FRONT)
    off.render(Scene(items=scene.items), FRONT)  # a new scene holding the same meshes
    off.render(Scene(items=(dataclasses.replace(a, pick_id=7), b)), FRONT)  # replace() keeps the texture
    with off.ctx:
        for _ in range(3):
            off.renderer.render(FRONT)
    assert off.renderer.texture_uploads - before == 1
    assert len(off.renderer.textures.entries) == 1
    off.render(Scene(items=(quad_mesh(leaf_like()),)), FRONT)
    assert off.renderer.texture_uploads - before == 2
    assert len(off.renderer.textures.entries) == 1  # the unused one was freed


def test_coverage_mipmaps_keep_the_cut_out_area_and_do_not_bleed():
    img = np.zeros((64, 40, 4), np.uint8)
    img[:] = (255, 0, 255, 0)  # transparent magenta
    img[:, np.arange(40) % 5 < 2] = (40, 200, 40, 255)  # thin opaque green stripes: 40% of the texels
    levels = coverage_mipmaps(img, 0.5)
    assert [lv.shape[:2] for lv in levels] == [(h, w) for w, h in mip_sizes(40, 64)]
    plain = img[..., 3:].astype(float) / 255
    for lv, (w, h) in zip(levels[1:], mip_sizes(40, 64)[1:], strict=True):
        plain = plain[: 2 * h, : 2 * w].reshape(h, 2, w, 2 if w < plain.shape[1] else 1).mean(axis=(1, 3))
        shown = lv[lv[..., 3] >= 128]
        assert len(shown) and (shown[:, 0] < 60).all() and (shown[:, 2] < 60).all()  # green, no magenta
        assert len(shown) / lv[..., 3].size >= 0.4  # never less than the full image: no vanishing
        if lv[..., 3].size >= 32:  # smaller levels cannot hold a 40% fraction of equal texels
            assert len(shown) / lv[..., 3].size <= 0.6
    assert (plain >= 0.5).mean() == 0.0  # plain averaged mipmaps lose the stripes entirely


@pytest.mark.parametrize("kwargs, field", [
    ({"texture": np.zeros((4, 4, 3), np.uint8), "uv": np.zeros((4, 2))}, "Mesh.texture"),
    ({"texture": np.zeros((4, 4, 4), np.float32), "uv": np.zeros((4, 2))}, "Mesh.texture"),
    ({"texture": np.zeros((4, 4, 4), np.uint8), "uv": np.zeros((3, 2))}, "Mesh.uv"),
    ({"texture": np.zeros((4, 4, 4), np.uint8)}, "Mesh.uv"),
    ({"normals": np.zeros((4, 2))}, "Mesh.normals"),
    ({"alpha_cutoff": 1.5}, "Mesh.alpha_cutoff"),
])
def test_bad_texture_input_is_one_validation_error_naming_the_field(kwargs, field):
    v, f = quad()
    with pytest.raises(ValidationError, match=field.replace(".", r"\.")):
        Mesh(v, f, **kwargs)


def test_a_writeable_texture_is_copied_and_a_read_only_one_shared():
    v, f = quad()
    mine = leaf_like()
    m = Mesh(v, f, uv=QUAD_UV, texture=mine)
    assert m.texture is not mine and not m.texture.flags.writeable
    mine[:] = 0
    assert m.texture[0, -1, 3] == 255  # the mesh's copy did not change
    assert Mesh(v, f, uv=QUAD_UV, texture=m.texture).texture is m.texture


@pytest.fixture(scope="module")
def tree_glb(tmp_path_factory) -> Path:
    from arboretum_library.export.gltf import write_glb
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.scene import tree_materials, tree_mesh

    tree = grow_tree(make_hbl(np.random.default_rng(4), n_main=2, n_lobes=3), GrowOptions(), np.random.default_rng(0))
    path = tmp_path_factory.mktemp("glb") / "tree.glb"
    write_glb(path, tree_mesh(tree).parts, tree_materials())
    return path


def leaf_pixels(img: np.ndarray) -> tuple[int, np.ndarray, int]:
    """Of an RGBA render: the count of clearly green pixels; the colour differences (sum over RGB) of
    horizontally adjacent pixels inside the green areas; the number of distinct colours there."""
    f = img[..., :3].astype(float)
    green = (f[..., 1] > 1.3 * f[..., 0]) & (f[..., 1] > 1.3 * f[..., 2]) & (f[..., 1] > 40)
    inner = green.copy()
    for shift in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        inner &= np.roll(green, shift, (0, 1))
    pairs = inner & np.roll(inner, -1, 1)
    steps = np.abs(f - np.roll(f, -1, 1)).sum(-1)[pairs]
    return int(green.sum()), steps, len(np.unique(f[inner].astype(int) @ [65536, 256, 1]))


def test_a_grown_tree_glb_shows_textured_leaves_not_cards(tree_glb):
    from arboretum_client.render_cli import load_scene
    from arboretum_client.scene_build import HBLStyle
    from arboretum_library.export.gltf_read import read_glb

    pos = next(g for g in read_glb(tree_glb) if g.alpha_mode == "MASK").positions
    low = pos[pos[:, 2] < np.median(pos[:, 2])].mean(axis=0)  # the lower leaf cluster
    cam = Camera(target=tuple(low), distance=0.6, azimuth=-90.0, elevation=10.0)
    with OffscreenRenderer((400, 400)) as r:
        textured = leaf_pixels(r.render(load_scene(tree_glb, HBLStyle(), True), cam))
        flat = leaf_pixels(r.render(load_scene(tree_glb, HBLStyle(), False), cam))
        assert r.renderer.texture_uploads == 2  # bark and leaf
    assert 0.3 * flat[0] < textured[0] < 0.85 * flat[0]  # cards cut to the leaf's outline
    assert np.median(flat[1]) == 0 and np.median(textured[1]) >= 2  # flat cards vs the texture's veins
    assert textured[2] > 1.5 * flat[2] and textured[2] > 400  # many more distinct greens


def test_render_cli_uses_the_glb_textures_unless_told_not_to(tree_glb, tmp_path):
    counts = {}
    for flag in (False, True):
        out = tmp_path / f"tree_{flag}.png"
        args = argparse.Namespace(inputs=[str(tree_glb)], out=str(out), view="front", size="400x600", points=False,
                                  no_grid=True, no_textures=flag, json=False)
        assert render_run(args) == 0
        counts[flag] = leaf_pixels(np.asarray(Image.open(out).convert("RGBA")))[0]
    assert 0 < counts[False] < 0.85 * counts[True]  # textured leaves cover less than flat cards
