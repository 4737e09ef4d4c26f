"""The client's rendering core: CPU geometry, camera framing, and pixels from headless EGL renders."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from arboretum_client.camera import VIEWS, Camera, fit_camera
from arboretum_client.render.meshes import _frames, tube_mesh, uv_sphere, vertex_normals
from arboretum_client.render_cli import parse_size, read_obj
from arboretum_client.scene import InstancedMesh, Mesh, PointSet, Polyline, Scene
from arboretum_client.scene_build import BRANCH_COLORS, LOBE_PALETTE, HBLStyle, hbl_scene
from arboretum_library.errors import InputError
from arboretum_library.model import HBL, Branch, Level, Lobe

GOLDEN = Path(__file__).parent / "golden"
SIZE = (320, 240)


def sphere_lobe(centre, radius, branch=-1) -> Lobe:
    v, f = uv_sphere(8, 12)
    return Lobe(points=np.zeros((0, 3)), hull_vertices=v * radius + centre, hull_faces=f,
                centre=np.asarray(centre, float), branch=branch)


def small_tree(with_lobe=True, with_points=False) -> HBL:
    """A vertical main branch 1 m tall, one secondary branch, one spherical lobe off to the side."""
    main = Branch(points=np.c_[np.zeros(6), np.zeros(6), np.linspace(0, 1, 6)], radii=np.linspace(0.03, 0.01, 6))
    sec = Branch(points=[[0, 0, 0.6], [0.2, 0, 0.75], [0.35, 0, 0.8]], radii=[0.01, 0.008, 0.005],
                 parent=0, parent_vertex=3, level=Level.SECONDARY)
    lobes = (sphere_lobe([0.55, 0.0, 0.85], 0.18, branch=1),) if with_lobe else ()
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(300, 3)) * 0.08 + [0.55, 0, 0.85] if with_points else np.zeros((0, 3))
    labels = np.ones(len(pts), np.uint8)
    return HBL(root=[0, 0, 0], branches=(main, sec), lobes=lobes, points=pts, labels=labels)


# -- pure numpy ----------------------------------------------------------------------------------
def test_tube_vertices_lie_at_their_radius_around_the_axis():
    axis = np.array([[0, 0, 0], [0.1, 0, 1], [0.4, 0.2, 2], [0.5, 0.5, 2.5]])
    radii = np.array([0.2, 0.15, 0.1, 0.05])
    v, n, f, owner = tube_mesh([(axis, radii), (axis[:2] + 3, radii[:2])], sides=8)
    assert len(v) == 8 * 6 + 4 and f.max() < len(v) and set(owner) == {0, 1}
    ring = v[owner == 0][:32].reshape(4, 8, 3)  # rings first, then the two cap centres
    dist = np.linalg.norm(ring - axis[:, None], axis=2)
    np.testing.assert_allclose(dist, np.broadcast_to(radii[:, None], dist.shape), rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-9)
    assert (np.sum(vertex_normals(v, f) * n, axis=1) > 0.3).all()  # faces wind outward


def test_frames_are_orthonormal_and_do_not_twist_on_a_straight_line():
    P = np.c_[np.zeros(10), np.zeros(10), np.arange(10.0)][None]
    T, N, B = _frames(P)
    np.testing.assert_allclose(np.einsum("blk,blk->bl", T, N), 0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(B, axis=2), 1, rtol=1e-12)
    np.testing.assert_allclose(N[0], np.broadcast_to(N[0, 0], N[0].shape), atol=1e-12)


@pytest.mark.parametrize("view", list(VIEWS))
def test_fit_camera_puts_every_box_corner_inside_the_frame(view):
    lo, hi = np.array([-0.3, -0.8, 0.0]), np.array([0.9, 0.4, 2.5])
    cam = fit_camera(np.stack([lo, hi]), view, aspect=16 / 9)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    px = cam.project(corners, (1600, 900))
    assert (px >= 0).all() and (px[:, 0] <= 1600).all() and (px[:, 1] <= 900).all()
    span = px.max(axis=0) - px.min(axis=0)
    assert span[0] > 0.8 * 1600 or span[1] > 0.8 * 900  # tight in at least one direction


def test_orbit_keeps_distance_and_clamps_elevation():
    cam = Camera(target=(1, 2, 3), distance=4.0, azimuth=10, elevation=80)
    turned = cam.orbit(30, 30)
    assert turned.elevation == 90 and turned.azimuth == 40
    assert np.isclose(np.linalg.norm(turned.eye - np.array([1, 2, 3])), 4.0)


def test_parse_size_and_obj_reader(tmp_path):
    assert parse_size("640x480") == (640, 480)
    with pytest.raises(InputError, match="WIDTHxHEIGHT"):
        parse_size("640by480")
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    verts, faces = read_obj(obj)
    assert verts.shape == (4, 3) and faces.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_hbl_scene_colours_and_names():
    sc = hbl_scene(small_tree(), HBLStyle(grid=False))
    assert [sc.names[it.pick_id] for it in sc.items] == ["branch:0", "branch:1", "lobe:0"]
    np.testing.assert_allclose(sc.items[0].color[:3], BRANCH_COLORS[Level.MAIN])
    np.testing.assert_allclose(sc.items[1].color[:3], BRANCH_COLORS[Level.SECONDARY])
    np.testing.assert_allclose(sc.items[2].color, [*LOBE_PALETTE[0], 0.3], rtol=1e-6)
    assert sc.items[1].radii.min() >= 0.003 * np.linalg.norm([0.73, 0.36, 1.03]) * 0.99  # minimum width


# -- GL ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def gl():
    from arboretum_client.context import create_headless_context

    ctx = create_headless_context()
    with ctx:  # stays current even if a test creates another context
        yield ctx
    ctx.release()


@pytest.fixture
def renderer(gl):
    from arboretum_client.render.renderer import Renderer

    assert gl.error == "GL_NO_ERROR"
    r = Renderer(gl, SIZE)
    yield r
    r.release()
    assert gl.error == "GL_NO_ERROR"


def draw(renderer, scene: Scene, camera: Camera) -> np.ndarray:
    renderer.upload(scene)
    renderer.render(camera)
    img = renderer.read()
    assert renderer.ctx.error == "GL_NO_ERROR"
    return img.astype(int)


def front(scene: Scene) -> Camera:
    return fit_camera(scene.bounds(), "front", aspect=SIZE[0] / SIZE[1])


def is_red(px) -> np.ndarray:
    px = np.asarray(px)
    return (px[..., 0] > 150) & (px[..., 1] < 90) & (px[..., 2] < 90)


@pytest.mark.gl
def test_main_branch_is_red_along_its_axis_and_nowhere_far_from_it(renderer):
    scene = hbl_scene(small_tree(with_lobe=False), HBLStyle(grid=False))
    scene = Scene(items=scene.items[:1], names=scene.names)
    cam = front(scene)
    img = draw(renderer, scene, cam)
    axis = cam.project(np.c_[np.zeros(9), np.zeros(9), np.linspace(0.1, 0.9, 9)], SIZE).round().astype(int)
    assert is_red(img[axis[:, 1], axis[:, 0]]).all()
    ys, xs = np.nonzero(is_red(img))
    assert len(xs) > 100
    assert np.abs(xs - axis[0, 0]).max() <= 12  # tube radius 0.03 m projects to < 10 px here


@pytest.mark.gl
def test_translucent_lobe_tints_the_background_with_its_palette_colour(renderer):
    tree = small_tree()
    cam = front(hbl_scene(tree, HBLStyle(grid=False)))
    with_lobe = draw(renderer, hbl_scene(tree, HBLStyle(grid=False)), cam)
    without = draw(renderer, hbl_scene(small_tree(with_lobe=False), HBLStyle(grid=False)), cam)
    x, y = cam.project([[0.62, 0, 0.95]], SIZE).round().astype(int)[0]  # inside the hull, clear of the branch
    tint = (with_lobe[y, x, :3] - without[y, x, :3]).astype(float)
    want = np.array(LOBE_PALETTE[0]) * 255 - without[y, x, :3]
    cos = tint @ want / (np.linalg.norm(tint) * np.linalg.norm(want))
    assert np.linalg.norm(tint) > 30 and cos > 0.9
    assert np.linalg.norm(tint) < 0.9 * np.linalg.norm(want)  # blended, not opaque
    corner = (5, 5)
    assert np.abs(with_lobe[corner] - without[corner]).max() == 0


@pytest.mark.gl
def test_points_and_thick_lines_render_where_they_project(renderer):
    pts = np.array([[0, 0, 0], [1, 0, 0.5], [-1, 0, 1], [0.5, 0, -0.3]])
    line = Polyline(points=[[-1, 0, -0.6], [1, 0, -0.6]], radii=[1, 1], color=(0, 0.8, 0), style="line", width_px=5)
    scene = Scene(items=(PointSet(points=pts, colors=np.tile([1.0, 0, 1], (4, 1)), size_px=7), line))
    cam = front(scene)
    img = draw(renderer, scene, cam)
    px = cam.project(pts, SIZE).astype(int)
    hit = img[px[:, 1], px[:, 0]]
    assert ((hit[:, 0] > 200) & (hit[:, 1] < 60) & (hit[:, 2] > 200)).all()
    off = img[px[:, 1] + 12, px[:, 0]]
    assert (off[:, 1] > 150).all()  # background (light grey) 12 px below each dot
    mid = cam.project([[0.3, 0, -0.6]], SIZE).astype(int)[0]
    col = img[mid[1] - 1 : mid[1] + 2, mid[0]]
    assert ((col[:, 1] > 150) & (col[:, 0] < 60)).all() and img[mid[1] + 8, mid[0], 0] > 150


@pytest.mark.gl
@pytest.mark.parametrize("view", list(VIEWS))
def test_fit_camera_frames_the_object(renderer, view):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    scene = Scene(items=(Mesh(vertices=v * [1.5, 1.0, 0.8] + [3, 2, 1], faces=f, pick_id=1),))  # a box
    cam = fit_camera(scene.bounds(), view, aspect=SIZE[0] / SIZE[1])
    img = draw(renderer, scene, cam)
    empty = draw(renderer, Scene(), cam)
    mask = np.abs(img - empty).max(axis=2) > 8
    assert not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    assert mask.mean() > 0.2


@pytest.mark.gl
def test_pick_returns_the_branch_id_on_a_branch_and_none_on_background(renderer):
    scene = hbl_scene(small_tree(), HBLStyle(grid=True))
    cam = front(scene)
    draw(renderer, scene, cam)
    x, y = cam.project([[0, 0, 0.3]], SIZE).round().astype(int)[0]
    assert scene.names[renderer.pick(x, y)] == "branch:0"
    lx, ly = cam.project([[0.62, 0, 0.95]], SIZE).round().astype(int)[0]
    assert scene.names[renderer.pick(lx, ly)] == "lobe:0"
    assert renderer.pick(3, 3) is None and renderer.pick(-1, 0) is None
    ids = renderer.render_ids()
    assert set(np.unique(ids)) == {0, 1, 2, 3}


@pytest.mark.gl
def test_instanced_meshes_take_one_draw_call_each_whatever_the_count(renderer):
    v, f = uv_sphere(4, 6)
    items = []
    for k, n in enumerate((10, 1000, 5000)):
        M = np.tile(np.eye(4), (n, 1, 1))
        M[:, :3, :3] *= 0.01
        M[:, :3, 3] = np.random.default_rng(k).uniform(-1, 1, (n, 3))
        items.append(InstancedMesh(mesh=Mesh(vertices=v, faces=f, color=(0.9, 0.6, 0.1), pick_id=k + 1), matrices=M))
    scene = Scene(items=tuple(items))
    img = draw(renderer, scene, fit_camera(scene.bounds(), "iso", SIZE[0] / SIZE[1]))
    assert renderer.stats.draw_calls == 1 + 3  # background + one per instanced mesh
    assert renderer.stats.triangles == len(f) * 6010
    orange = (img[..., 0] > 150) & (img[..., 2] < 80)
    assert orange.mean() > 0.01


def test_context_error_names_the_missing_packages(monkeypatch):
    import moderngl

    from arboretum_client import context

    def fail(**kw):
        raise Exception("libEGL.so: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    with pytest.raises(context.ContextError, match="libegl1 libgl1 libgles2"):
        context.create_headless_context()


# -- golden image --------------------------------------------------------------------------------
@pytest.mark.gl
def test_golden_image_on_llvmpipe(renderer, gl):
    from PIL import Image

    if "llvmpipe" not in gl.info["GL_RENDERER"]:
        pytest.skip(f"golden images are for Mesa llvmpipe only, this is {gl.info['GL_RENDERER']}")
    scene = hbl_scene(small_tree(with_points=True), HBLStyle(show_points=True))
    img = draw(renderer, scene, fit_camera(scene.bounds(), "iso", SIZE[0] / SIZE[1])).astype(np.uint8)
    path = GOLDEN / "small_tree_iso.png"
    if os.environ.get("ARBORETUM_REGEN_GOLDEN") == "1" or not path.exists():
        Image.fromarray(img).save(path)
        if os.environ.get("ARBORETUM_REGEN_GOLDEN") != "1":
            pytest.fail(f"golden image {path} was missing and has been written; rerun")
    golden = np.asarray(Image.open(path).convert("RGBA")).astype(int)
    diff = np.abs(img.astype(int) - golden).max(axis=2)
    if diff.mean() > 1.0 or (diff > 40).mean() > 0.005:
        out = Path(tempfile.mkdtemp(prefix="arboretum-golden-"))
        Image.fromarray(img).save(out / "actual.png")
        Image.fromarray(np.clip(diff * 4, 0, 255).astype(np.uint8)).save(out / "diff.png")
        pytest.fail(f"render differs from {path.name} (mean {diff.mean():.2f}); see {out}")


@pytest.mark.gl
def test_supersampling_fallback_matches_msaa(gl):
    from arboretum_client.render.renderer import Renderer

    scene = hbl_scene(small_tree(), HBLStyle(grid=False))
    cam = front(scene)
    images = {}
    for mode in ("msaa", "supersample", "none"):
        r = Renderer(gl, SIZE, antialias=mode)
        images[mode] = draw(r, scene, cam)
        assert r.read().shape == (SIZE[1], SIZE[0], 4)
        r.release()
    diff = np.abs(images["msaa"] - images["supersample"]).max(axis=2)
    assert diff.mean() < 1.0 and (diff > 60).mean() < 0.002
    edges = np.abs(images["msaa"] - images["none"]).max(axis=2)
    assert (edges > 0).sum() > 20  # anti-aliasing did change the edges
    assert gl.error == "GL_NO_ERROR"


@pytest.mark.gl
def test_cli_renders_an_hbl_record_and_a_mesh(tmp_path, gl):
    import json
    import subprocess
    import sys

    from PIL import Image

    from arboretum_library.codec import save_record

    record = save_record(tmp_path / "tree.npz", small_tree())
    obj = tmp_path / "box.obj"
    obj.write_text("v 1 -0.1 0\nv 1.2 -0.1 0\nv 1.2 -0.1 0.2\nv 1 -0.1 0.2\nf 1 2 3 4\n")
    out = tmp_path / "pic.png"
    cmd = [sys.executable, "-m", "arboretum_library.cli", "render", str(record), str(obj), "--out", str(out),
           "--view", "front", "--size", "320x240", "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["size"] == [320, 240] and summary["triangles"] > 100
    img = np.asarray(Image.open(out)).astype(int)
    assert img.shape == (240, 320, 4) and is_red(img).sum() > 100
    bad = subprocess.run(cmd[:4] + [str(tmp_path / "missing.xyz"), "--out", str(out)], capture_output=True, text=True)
    assert bad.returncode == 2 and "missing.xyz: no such file" in bad.stderr


def test_load_hbl_reads_record_files(tmp_path):
    from arboretum_client.render_cli import load_hbl
    from arboretum_library.codec import arrays_to_npz, save_record

    tree = small_tree()
    h = load_hbl(save_record(tmp_path / "a.npz", tree))
    assert len(h.branches) == 2 and len(h.lobes) == 1
    np.testing.assert_array_equal(h.branches[0].points, tree.branches[0].points)
    (tmp_path / "c.npz").write_bytes(arrays_to_npz({"x": np.zeros(3)}))
    with pytest.raises(InputError, match="not an Arboretum record"):
        load_hbl(tmp_path / "c.npz")
