"""The GLB reader (library/export/gltf_read.py) and rendering GLBs with the client.

Round trips through Arboretum's own writers (grown trees from the server's grow stage, module trees
from its modules export), hand-built files for the parts of glTF our writers never produce (TRS
nodes, children, strides, normalised integers, no indices), one InputError per malformed file, and
headless renders: bark-coloured trunk, green crown, one draw call per module type.
"""

from __future__ import annotations

import io
import json
import struct

import numpy as np
import pytest

from arboretum_client.scene import InstancedMesh, Mesh
from arboretum_client.scene_build import glb_items, glb_scene, texture_mean_color
from arboretum_library.assets import asset_path
from arboretum_library.errors import InputError
from arboretum_library.export.gltf import glb_bytes, write_glb
from arboretum_library.export.gltf_read import parse_glb, read_glb
from arboretum_library.export.instanced import instanced_glb_bytes, plain_nodes_glb_bytes
from arboretum_library.export.parts import Material, MeshPart, Node
from arboretum_library.geometry import axis_angle_matrix, make_transform, yup_to_zup, zup_to_yup

SIZE = (320, 400)


# -- fixtures: files made by Arboretum's writers ---------------------------------------------------
@pytest.fixture(scope="module")
def grown():
    from arboretum_server.grow.demo import demo_hbl
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.scene import tree_materials, tree_mesh

    tree = grow_tree(demo_hbl(np.random.default_rng(4), n_lobes=16, height=4.0), GrowOptions(),
                     np.random.default_rng(0))
    mesh = tree_mesh(tree)
    return tree, mesh, glb_bytes(mesh.parts, tree_materials())


@pytest.fixture(scope="module")
def modules():
    from arboretum_server.modules.crown import crown_from_meshes
    from arboretum_server.modules.export import from_modular_tree
    from arboretum_server.modules.grow import grow_modular_tree
    from arboretum_server.modules.moduleset import load_module_set
    from arboretum_server.modules.options import ModularTreeOptions
    from arboretum_server.modules.shapes import tetrahedron_mesh

    mods = load_module_set(asset_path("modules", "default"))
    crown = crown_from_meshes([tetrahedron_mesh([0, 0, 4.5], 6.5)])
    tree = grow_modular_tree(mods, crown, ModularTreeOptions(), np.random.default_rng(1))
    return from_modular_tree(tree, mods)


def glb(doc: dict, blob: bytes = b"") -> bytes:
    """A GLB of a JSON document and a BIN chunk (the test's own minimal packer)."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + (struct.pack("<I4s", len(blob), b"BIN\0") + blob if blob else b"")
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


# -- round trips -----------------------------------------------------------------------------------
def test_grown_tree_reads_back_in_the_world_frame(grown):
    tree, mesh, data = grown
    bark, leaves = parse_glb(data, "tree.glb")
    assert (bark.name, leaves.name) == ("bark", "leaves")
    for got, part in ((bark, mesh.bark), (leaves, mesh.leaves)):
        np.testing.assert_allclose(got.positions, part.positions, atol=1e-6 * np.abs(part.positions).max())
        np.testing.assert_array_equal(got.faces, part.faces)
        assert got.faces.dtype == np.int32 and got.positions.dtype == np.float64
        np.testing.assert_allclose(got.normals, part.normals, atol=1e-6)
        np.testing.assert_array_equal(got.uvs, np.asarray(part.uv, np.float32))
        np.testing.assert_array_equal(got.instances, np.eye(4)[None])
    assert len(bark.faces) + len(leaves.faces) == mesh.triangles
    assert bark.positions[:, 2].min() < 0.05 < 1.0 < bark.positions[:, 2].max()  # Z is up again
    assert bark.texture == asset_path("textures", "bark.png").read_bytes()
    assert leaves.texture == asset_path("textures", "leaf.png").read_bytes()
    assert (bark.alpha_mode, bark.double_sided) == ("OPAQUE", False)
    assert (leaves.alpha_mode, leaves.double_sided) == ("MASK", True)


@pytest.mark.parametrize("plain", [False, True])
def test_module_instances_read_back_as_written(modules, plain):
    make = plain_nodes_glb_bytes if plain else instanced_glb_bytes
    got = parse_glb(make(modules.meshes, [Material("bark", (0.35, 0.25, 0.17, 1))], modules.module,
                         modules.T_world_module), "modules.glb")
    assert [g.name for g in got] == [m.name for m in modules.meshes]  # one record per module type
    for k, g in enumerate(got):
        part = modules.meshes[k]
        np.testing.assert_allclose(g.positions, part.positions, atol=1e-6)
        assert len(g.faces) == len(part.faces)
        T = modules.T_world_module[modules.module == k]
        assert g.instances.shape == T.shape
        np.testing.assert_allclose(g.instances, T, atol=2e-6 * max(1.0, np.abs(T).max()))
        np.testing.assert_allclose(g.base_color, [0.35, 0.25, 0.17, 1], atol=1e-7)
    assert sum(len(g.faces) * len(g.instances) for g in got) == modules.triangles


def test_nodes_sharing_a_mesh_become_instances_of_it(tmp_path):
    part = MeshPart("tri", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    T = make_transform(axis_angle_matrix([0, 0, 1], np.pi / 2), [0, 0, 2.0], scale=0.5)
    write_glb(tmp_path / "two.glb", [part], [Material("grey", (0.5, 0.5, 0.5, 1))], [Node(0), Node(0, T)])
    (g,) = read_glb(tmp_path / "two.glb")
    np.testing.assert_allclose(g.instances, [np.eye(4), T], atol=1e-12)


def test_trs_children_strides_normalised_and_unindexed():
    """Parent translation, child rotation + scale, an extra matrix node; interleaved positions with
    byteStride 16 and normalised uint8 colours between them; a primitive without indices."""
    pos_yup = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1]], np.float32)
    inter = np.zeros((6, 4), np.float32)
    inter[:, :3] = pos_yup
    inter.view(np.uint8).reshape(6, 16)[:, 12:] = [255, 0, 51, 0]  # 4 normalised uint8s after each xyz
    q = np.r_[np.sin(np.pi / 4) * np.array([0, 1.0, 0]), np.cos(np.pi / 4)]  # 90 deg about glTF Y
    matrix = np.eye(4)
    matrix[:3, 3] = [5, 0, 0]
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": 96}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 96, "byteStride": 16}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 6, "type": "VEC3"},
                         {"bufferView": 0, "byteOffset": 12, "componentType": 5121, "count": 6,
                          "type": "VEC4", "normalized": True}],
           "meshes": [{"name": "m", "primitives": [{"attributes": {"POSITION": 0}}]}],
           "nodes": [{"translation": [0, 3, 0], "children": [1]},
                     {"mesh": 0, "rotation": list(q), "scale": [2, 2, 2]},
                     {"mesh": 0, "matrix": list(matrix.T.reshape(-1))}],
           "scenes": [{"nodes": [0, 2]}], "scene": 0}
    (g,) = parse_glb(glb(doc, inter.tobytes()), "hand.glb")
    np.testing.assert_allclose(g.positions, yup_to_zup(pos_yup.astype(np.float64)))
    np.testing.assert_array_equal(g.faces, [[0, 1, 2], [3, 4, 5]])
    # the first placement maps a mesh point p (Z up) to the world: child R S, then parent translation
    p = np.array([1.0, 0, 0])
    world_yup = np.array([0, 3, 0]) + 2 * np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]]) @ zup_to_yup(p)
    T0, T1 = g.instances
    np.testing.assert_allclose(T0[:3, :3] @ p + T0[:3, 3], yup_to_zup(world_yup), atol=1e-12)
    np.testing.assert_allclose(T1, make_transform(t=yup_to_zup(np.array([5.0, 0, 0]))), atol=1e-12)
    from arboretum_library.export.gltf_read import _Reader

    colors = _Reader(doc, inter.tobytes(), "hand.glb").accessor(1)
    np.testing.assert_allclose(colors, np.tile([1.0, 0.0, 0.2, 0.0], (6, 1)))


# -- malformed files -------------------------------------------------------------------------------
def _good() -> tuple[dict, bytes]:
    blob = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
           "scenes": [{"nodes": [0]}]}
    return doc, blob


def _with(**changes) -> bytes:
    doc, blob = _good()
    for key, value in changes.items():
        doc[key] = value
    return glb(doc, blob)


def _bad_chunk() -> bytes:
    """A GLB whose BIN chunk claims 999 bytes but the file (with a consistent header) ends first."""
    body = glb(_good()[0])[12:] + struct.pack("<I4s", 999, b"BIN\0") + b"\0" * 16
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


MALFORMED = {
    "short": (b"glTF\x02\0", "too short"),
    "magic": (b"GLTF" + glb(*_good())[4:], "magic"),
    "version": (glb(*_good())[:4] + struct.pack("<I", 1) + glb(*_good())[8:], "version 1"),
    "truncated": (glb(*_good())[:-8], "truncated"),
    "chunk": (_bad_chunk(), "truncated b'BIN"),
    "not json": (struct.pack("<4sII", b"glTF", 2, 24) + struct.pack("<I4s", 4, b"JSON") + b"{{{{", "not valid JSON"),
    "out of range": (_with(accessors=[{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"}]),
                     "accessor 0 out of range"),
    "sparse": (_with(accessors=[{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                                 "sparse": {"count": 1}}]), "not supported"),
    "bad index": (_with(nodes=[{"mesh": 3}]), "malformed glTF JSON"),
    "cycle": (_with(nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}]), "cycle"),
    "lines": (_with(meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "mode": 1}]}]), "mode 1"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_give_one_input_error_naming_the_file(tmp_path, case):
    data, problem = MALFORMED[case]
    path = tmp_path / f"bad_{case.replace(' ', '_')}.glb"
    path.write_bytes(data)
    with pytest.raises(InputError) as err:
        read_glb(path)
    assert str(path) in str(err.value) and problem in str(err.value)
    assert parse_glb(glb(*_good()), "ok.glb")[0].faces.tolist() == [[0, 1, 2]]  # the base file is fine


# -- client scenes ---------------------------------------------------------------------------------
def test_texture_mean_colour_ignores_cut_out_texels():
    from PIL import Image

    rgba = np.zeros((4, 4, 4), np.uint8)
    rgba[:, :2] = [255, 0, 0, 0]  # transparent red: cut out
    rgba[:, 2:] = [0, 200, 0, 255]
    buf = io.BytesIO()
    Image.fromarray(rgba).save(buf, format="PNG")
    np.testing.assert_allclose(texture_mean_color(buf.getvalue()), [0, 200 / 255, 0])
    np.testing.assert_array_equal(texture_mean_color(b"not an image"), [1, 1, 1])


def test_scene_items_colour_and_instancing(grown, modules):
    _, _, data = grown
    bark, leaves = glb_items(parse_glb(data))[0]
    assert isinstance(bark, Mesh) and isinstance(leaves, Mesh)
    r, g, b = bark.color[:3]
    assert r > g > b and r - b > 0.1  # the bark texture's brown
    r, g, b = leaves.color[:3]
    assert g > r + 0.15 and g > b + 0.15  # the leaf texture's green (transparent texels left out)
    got = parse_glb(instanced_glb_bytes(modules.meshes, [Material("b")], modules.module, modules.T_world_module))
    items, names = glb_items(got)
    assert sum(isinstance(it, InstancedMesh) for it in items) == sum(len(g.instances) > 1 for g in got)
    assert sorted(names.values()) == sorted(m.name for m in modules.meshes)


# -- headless renders ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def renderer():
    from arboretum_client.context import create_headless_context
    from arboretum_client.render.renderer import Renderer

    ctx = create_headless_context()
    with ctx:
        r = Renderer(ctx, SIZE)
        yield r
        r.release()
        assert ctx.error == "GL_NO_ERROR"
    ctx.release()


def _render(renderer, scene, view="front"):
    from arboretum_client.camera import fit_camera

    camera = fit_camera(scene.bounds(), view, aspect=SIZE[0] / SIZE[1])
    renderer.upload(scene)
    renderer.render(camera)
    assert renderer.ctx.error == "GL_NO_ERROR"
    return renderer.read().astype(int), camera


def _is_bark(px):
    return (px[..., 0] > px[..., 2] + 20) & (px[..., 0] >= px[..., 1]) & (px[..., 1] > px[..., 2])


def _is_leaf(px):
    return (px[..., 1] > px[..., 0] + 20) & (px[..., 1] > px[..., 2] + 20)


def _trunk_points(tree, up_to: float) -> np.ndarray:
    """(10, 3) points along the trunk axis up to height ``up_to``: from the root, always to the
    thickest child."""
    from arboretum_library.geometry import resample_polyline

    chain = [0]
    while tree.positions[chain[-1], 2] < up_to:
        children = np.flatnonzero(tree.parents == chain[-1])
        if not len(children):
            break
        chain.append(int(children[np.argmax(tree.radii[children])]))
    return resample_polyline(tree.positions[chain], 12)[1:-1]


@pytest.mark.gl
def test_grown_tree_renders_brown_trunk_and_green_crown(renderer, grown):
    tree, _, data = grown
    img, cam = _render(renderer, glb_scene(parse_glb(data), grid=False))
    trunk = _trunk_points(tree, 0.25 * tree.positions[:, 2].max())
    xy = np.round(cam.project(trunk, SIZE)).astype(int)
    assert _is_bark(img[xy[:, 1], xy[:, 0]]).mean() > 0.9
    leaf_xy = np.round(cam.project(tree.leaves.centres, SIZE)).astype(int)
    assert _is_leaf(img[leaf_xy[:, 1], leaf_xy[:, 0]]).mean() > 0.4
    assert _is_leaf(img).sum() > 500
    below = int(leaf_xy[:, 1].max()) + 10  # under the lowest leaf: bark and background, no green
    assert _is_leaf(img[below:]).sum() == 0 and _is_bark(img[below:]).sum() > 50


@pytest.mark.gl
@pytest.mark.parametrize("plain", [False, True])
def test_module_tree_is_one_draw_call_per_module_type(renderer, modules, plain):
    make = plain_nodes_glb_bytes if plain else instanced_glb_bytes
    data = make(modules.meshes, [Material("bark", (0.35, 0.25, 0.17, 1))], modules.module, modules.T_world_module)
    img, _ = _render(renderer, glb_scene(parse_glb(data), grid=False), "iso")
    stats = renderer.stats
    assert stats.draw_calls == 1 + len(modules.meshes)  # background + one per module type
    assert stats.triangles == modules.triangles
    assert _is_bark(img).sum() > 1000


@pytest.mark.gl
def test_cli_renders_a_glb_and_rejects_a_broken_one(tmp_path, grown):
    import subprocess
    import sys

    _, mesh, data = grown
    (tmp_path / "tree.glb").write_bytes(data)
    (tmp_path / "bad.glb").write_bytes(data[:100])
    cmd = [sys.executable, "-m", "arboretum_library.cli", "render", "--size", "160x120", "--json"]
    done = subprocess.run([*cmd, str(tmp_path / "tree.glb"), "--out", str(tmp_path / "t.png")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["triangles"] == mesh.triangles
    bad = subprocess.run([*cmd, str(tmp_path / "bad.glb"), "--out", str(tmp_path / "b.png")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "bad.glb: truncated" in bad.stderr and "Traceback" not in bad.stderr
