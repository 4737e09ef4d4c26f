"""GLB and USD of a tree at UTM coordinates: float32 positions relative to a local origin, the offset in
float64 on the root node / prim, so every importer puts each vertex within 1 mm of where it belongs."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from arboretum_library.export.gltf import glb_bytes
from arboretum_library.export.instanced import instanced_glb_bytes
from arboretum_library.export.parts import Material, MeshPart
from arboretum_library.geometry import zup_to_yup
from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.tree import grow_tree
from arboretum_server.mesh.scene import tree_materials, tree_mesh

UTM = np.array([500000.0, 5400000.0, 0.0])
MM = 1e-3


@pytest.fixture(scope="module")
def far_parts():
    """The bark and leaves of a small grown tree, moved to UTM coordinates (float64)."""
    tree = grow_tree(demo_hbl(np.random.default_rng(5), n_lobes=3), GrowOptions(), np.random.default_rng(1))
    mesh = tree_mesh(tree)
    parts = [MeshPart(p.name, p.positions + UTM, p.faces, p.normals, p.uv, p.material) for p in mesh.parts]
    assert len(parts[0].faces) > 10000 and len(parts[1].faces) > 100
    return parts


def _json(data: bytes) -> dict:
    length = struct.unpack_from("<I", data, 12)[0]
    return json.loads(data[20:20 + length])


def _area(p: np.ndarray, f: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1)


def test_trimesh_places_a_utm_tree_within_a_millimetre(far_parts, tmp_path):
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path / "far.glb"
    path.write_bytes(glb_bytes(far_parts, tree_materials(textures=False)))
    scene = trimesh.load(path, process=False)
    world = {}
    for node in scene.graph.nodes_geometry:
        T, geom = scene.graph[node]
        v = np.asarray(scene.geometry[geom].vertices, np.float64)
        world[geom] = v @ T[:3, :3].T + T[:3, 3]
    assert set(world) == {"bark", "leaves"}
    for part in far_parts:
        err = np.abs(world[part.name] - zup_to_yup(part.positions)).max()  # Y up, offset converted too
        assert err < MM, (part.name, err)


def test_float32_triangles_of_a_utm_tree_are_not_degenerate(far_parts):
    pygltflib = pytest.importorskip("pygltflib")
    data = glb_bytes(far_parts, tree_materials(textures=False))
    g = pygltflib.GLTF2.load_from_bytes(data)
    blob = g.binary_blob()
    root = [n for n in g.nodes if n.name == "origin"]
    offset = np.array(root[0].translation) if root else np.zeros(3)
    for mesh, part in zip(g.meshes, far_parts):
        prim = mesh.primitives[0]
        acc = g.accessors[prim.attributes.POSITION]
        view = g.bufferViews[acc.bufferView]
        pos = np.frombuffer(blob, np.float32, acc.count * 3, view.byteOffset).reshape(-1, 3)
        assert (_area(pos.astype(np.float64), part.faces) > 0).all()
        assert np.abs(pos + offset - zup_to_yup(part.positions)).max() < MM
        assert np.abs(pos).max() < 100.0  # stored near the local origin
    allpos = np.concatenate([p.positions for p in far_parts])
    assert len(root) == 1 and g.scenes[0].nodes == [g.nodes.index(root[0])]
    np.testing.assert_array_equal(offset, zup_to_yup(np.round((allpos.min(0) + allpos.max(0)) / 2)))


def test_instanced_glb_translations_relative_to_a_root(tmp_path):
    pygltflib = pytest.importorskip("pygltflib")
    from arboretum_library.export.gltf_read import parse_glb

    cube = MeshPart("m", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) * 0.01,
                    np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    rng = np.random.default_rng(0)
    T = np.tile(np.eye(4), (50, 1, 1))
    T[:, :3, 3] = UTM + rng.uniform(-20, 20, (50, 3))
    data = instanced_glb_bytes([cube], [Material("m")], np.zeros(50, np.int64), T)
    (placed,) = parse_glb(data)
    np.testing.assert_allclose(placed.instances[:, :3, 3], T[:, :3, 3], rtol=0, atol=MM)
    g = pygltflib.GLTF2.load_from_bytes(data)
    inst_node = next(n for n in g.nodes if n.extensions)
    root = next(n for n in g.nodes if n.name == "origin")
    acc = g.accessors[inst_node.extensions["EXT_mesh_gpu_instancing"]["attributes"]["TRANSLATION"]]
    view = g.bufferViews[acc.bufferView]
    t = np.frombuffer(g.binary_blob(), np.float32, acc.count * 3, view.byteOffset).reshape(-1, 3)
    assert np.abs(t).max() < 40.0
    np.testing.assert_allclose(t + np.array(root.translation), zup_to_yup(T[:, :3, 3]), rtol=0, atol=MM)


def test_plain_nodes_glb_translations_relative_to_a_root():
    """``--plain-nodes``: each node matrix holds its translation minus the root's, so float32 engines place
    every instance within 1 mm (before: the full 5.4e6 m in every matrix, instances moved by up to 0.2 m)."""
    from arboretum_library.export.gltf_read import parse_glb
    from arboretum_library.export.instanced import plain_nodes_glb_bytes

    cube = MeshPart("m", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) * 0.01,
                    np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    rng = np.random.default_rng(0)
    T = np.tile(np.eye(4), (30, 1, 1))
    a = rng.uniform(0, 2 * np.pi, 30)
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    T[:, :3, :3] *= rng.uniform(0.5, 2.0, 30)[:, None, None]
    T[:, :3, 3] = UTM + rng.uniform(-20, 20, (30, 3))
    data = plain_nodes_glb_bytes([cube], [Material("m")], np.zeros(30, np.int64), T)
    (placed,) = parse_glb(data)
    np.testing.assert_allclose(placed.instances, T, rtol=0, atol=MM)
    doc = _json(data)
    root = doc["nodes"][doc["scenes"][0]["nodes"][0]]
    assert doc["scenes"][0]["nodes"] == [30] and root["name"] == "origin" and root["children"] == list(range(30))
    np.testing.assert_array_equal(root["translation"], zup_to_yup(np.round((T[:, :3, 3].min(0) + T[:, :3, 3].max(0)) / 2)))
    M = np.array([n["matrix"] for n in doc["nodes"][:30]], np.float32).reshape(-1, 4, 4)  # column-major
    t = M[:, 3, :3].astype(np.float64)  # as a float32 engine reads it
    assert np.abs(t).max() < 40.0
    np.testing.assert_allclose(t + root["translation"], zup_to_yup(T[:, :3, 3]), rtol=0, atol=MM)


def test_usd_mesh_and_instancer_at_utm(far_parts, tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    from arboretum_library.export.usd import read_usd_instancer, write_usd_instanced, write_usd_mesh

    bark = far_parts[0]
    write_usd_mesh(tmp_path / "far.usdc", bark)
    stage = Usd.Stage.Open(str(tmp_path / "far.usdc"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Tree/Mesh"))
    local = np.asarray(mesh.GetPointsAttr().Get(), np.float64)
    assert (_area(local, bark.faces) > 0).all()
    M = np.array(mesh.ComputeLocalToWorldTransform(Usd.TimeCode.Default()))  # row vectors
    world = local @ M[:3, :3] + M[3, :3]
    assert np.abs(world - bark.positions).max() < MM
    ops = UsdGeom.Xform(stage.GetPrimAtPath("/Tree")).GetOrderedXformOps()
    assert [op.GetPrecision() for op in ops] == [UsdGeom.XformOp.PrecisionDouble]
    T = np.tile(np.eye(4), (20, 1, 1))
    T[:, :3, 3] = UTM + np.random.default_rng(1).uniform(-20, 20, (20, 3))
    write_usd_instanced(tmp_path / "inst.usda", [bark], np.zeros(20, np.int64), T)
    got = read_usd_instancer(tmp_path / "inst.usda")
    np.testing.assert_allclose(got["positions"], T[:, :3, 3], rtol=0, atol=MM)


def test_near_scene_is_written_as_it_is():
    part = MeshPart("m", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]) + [100.0, -50.0, 3.0],
                    np.array([[0, 1, 2]]))
    doc = _json(glb_bytes([part], []))
    assert [n["name"] for n in doc["nodes"]] == ["m"] and "translation" not in doc["nodes"][0]
    assert doc["accessors"][0]["max"] == [101.0, 3.0, 50.0]
