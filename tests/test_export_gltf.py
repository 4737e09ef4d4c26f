"""GLB export: the Khronos glTF-Validator reports no error, trimesh reads back the same triangles,
Y is up, textures and materials are embedded, nodes can share a mesh."""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from arboretum_library.export.gltf import glb_bytes, write_glb
from arboretum_library.export.parts import Material, MeshPart, Node
from arboretum_library.geometry import axis_angle_matrix, make_transform
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.tree import grow_tree
from arboretum_server.mesh.scene import tree_materials, tree_mesh
from factories import make_hbl

VALIDATOR = Path(__file__).resolve().parents[1] / "tools" / "gltf-validator"


def validate(path: Path) -> dict:
    """The glTF-Validator's JSON report of ``path`` (skips when node or the validator is missing)."""
    if shutil.which("node") is None or not (VALIDATOR / "node_modules" / "gltf-validator").is_dir():
        pytest.skip("glTF-Validator not installed: run 'npm ci --prefix tools/gltf-validator'")
    proc = subprocess.run(["node", str(VALIDATOR / "validate.mjs"), str(path)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode in (0, 1), proc.stderr
    return json.loads(proc.stdout)


@pytest.fixture(scope="module")
def grown():
    t = grow_tree(make_hbl(np.random.default_rng(4), n_main=2, n_lobes=3), GrowOptions(),
                  np.random.default_rng(0))
    return t, tree_mesh(t)


def test_tree_glb_is_valid_and_reads_back(tmp_path, grown):
    tree, mesh = grown
    path = tmp_path / "tree.glb"
    write_glb(path, mesh.parts, tree_materials())
    report = validate(path)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]
    assert report["issues"]["numWarnings"] == 0, report["issues"]["messages"][:5]
    scene = trimesh.load(path)
    assert sum(len(g.faces) for g in scene.geometry.values()) == mesh.triangles
    assert len(mesh.leaves.faces) > 100  # the leaves survive export


def test_glb_is_y_up_with_embedded_textures(tmp_path, grown):
    tree, mesh = grown
    data = glb_bytes(mesh.parts, tree_materials())
    length, kind = struct.unpack_from("<I4s", data, 12)
    doc = json.loads(data[20:20 + length])
    assert kind == b"JSON" and struct.unpack_from("<I", data, 8)[0] == len(data)
    pos = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    bark = mesh.bark.positions
    assert pos["max"][1] == pytest.approx(bark[:, 2].max(), abs=1e-5)  # glTF Y = world Z
    assert pos["min"][2] == pytest.approx(-bark[:, 1].max(), abs=1e-5)  # glTF Z = -world Y
    assert len(doc["images"]) == 2 and all(im["mimeType"] == "image/png" for im in doc["images"])
    leaf = doc["materials"][1]
    assert leaf["alphaMode"] == "MASK" and leaf["doubleSided"] is True
    blob = data[20 + length + 8:]
    view = doc["bufferViews"][doc["images"][0]["bufferView"]]
    assert blob[view["byteOffset"]:view["byteOffset"] + 8] == b"\x89PNG\r\n\x1a\n"


def test_nodes_sharing_a_mesh(tmp_path):
    """Two plain nodes instance one mesh; the second is rotated 90 deg about world Z and lifted 2 m."""
    box = trimesh.creation.box((1, 1, 1))
    part = MeshPart("box", box.vertices, box.faces, box.vertex_normals, None, 0)
    T = make_transform(axis_angle_matrix([0, 0, 1], np.pi / 2), [0, 0, 2.0])
    path = tmp_path / "inst.glb"
    write_glb(path, [part], [Material("grey", (0.5, 0.5, 0.5, 1))], [Node(0), Node(0, T, "lifted")])
    report = validate(path)
    assert report["issues"]["numErrors"] == 0
    scene = trimesh.load(path)
    assert sum(len(g.faces) for g in scene.dump()) == 24
    lifted = [g for g in scene.dump() if g.bounds[1][1] > 2.0]  # Y up in glTF: lifted along +Y
    assert len(lifted) == 1 and lifted[0].bounds[0][1] == pytest.approx(1.5)


def test_tree_without_lobes_exports_bark_only(tmp_path):
    """No lobes: no twigs and no leaves; the empty leaf mesh is left out and the file stays valid."""
    from arboretum_library.model import HBL

    h = make_hbl(np.random.default_rng(4), n_main=2, n_lobes=2)
    bare = HBL(h.root, h.branches, ())
    t = grow_tree(bare, GrowOptions(step=0.02), np.random.default_rng(0))
    mesh = tree_mesh(t)
    assert t.twig_count == 0 and len(mesh.leaves.faces) == 0
    path = tmp_path / "bare.glb"
    write_glb(path, mesh.parts, tree_materials())
    assert validate(path)["issues"]["numErrors"] == 0
    assert sum(len(g.faces) for g in trimesh.load(path).geometry.values()) == len(mesh.bark.faces)
