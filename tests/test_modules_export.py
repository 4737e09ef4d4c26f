"""Instanced export of a modular tree: EXT_mesh_gpu_instancing GLB, plain-node GLB, USD PointInstancer.

Files are checked by independent tools: the Khronos glTF-Validator, pygltflib (decodes the instance
accessors), trimesh (plain nodes), pxr.Usd and pxr.UsdValidation.
"""

from __future__ import annotations

import struct

import numpy as np
import pygltflib
import pytest
import trimesh

from arboretum_library.assets import asset_path
from arboretum_library.errors import ValidationError
from arboretum_library.export.gltf import C_YUP_ZUP
from arboretum_library.export.instanced import (
    EXTENSION,
    decompose_similarity,
    instanced_glb_bytes,
    matrix_to_quat_xyzw,
)
from arboretum_library.geometry import axis_angle_matrix, make_transform, quat_to_matrix, zup_to_yup
from arboretum_server.modules.crown import crown_from_meshes
from arboretum_server.modules.export import (
    BARK,
    flat_part,
    flat_size,
    from_modular_tree,
    write_instances,
)
from arboretum_server.modules.grow import grow_modular_tree
from arboretum_server.modules.moduleset import load_module_set
from arboretum_server.modules.options import ModularTreeOptions
from arboretum_server.modules.report import constraint_report, size_report
from arboretum_server.modules.shapes import tetrahedron_mesh
from test_export_gltf import validate

COMPONENTS = {5126: np.float32}
WIDTH = {"VEC3": 3, "VEC4": 4}


@pytest.fixture(scope="module")
def grown():
    modules = load_module_set(asset_path("modules", "default"))
    crown = crown_from_meshes([tetrahedron_mesh([0, 0, 4.5], 6.5)])
    tree = grow_modular_tree(modules, crown, ModularTreeOptions(), np.random.default_rng(1))
    return modules, tree, from_modular_tree(tree, modules)


def _accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    blob = gltf.binary_blob()
    start = view.byteOffset + (acc.byteOffset or 0)
    n = acc.count * WIDTH[acc.type]
    return np.frombuffer(blob, COMPONENTS[acc.componentType], n, start).reshape(acc.count, -1)


def _T_from_trs_yup(t, q, s) -> np.ndarray:
    """World (Z up) 4x4 of a glTF (Y up) translation, xyzw quaternion and scale."""
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(np.r_[q[3], q[:3]]) * s[0]
    T[:3, 3] = t
    C = np.eye(4)
    C[:3, :3] = C_YUP_ZUP
    return C.T @ T @ C


def test_instanced_glb_is_valid_and_decodes_exactly(tmp_path, grown):
    modules, tree, inst = grown
    path = tmp_path / "tree.glb"
    write_instances(path, inst)
    report = validate(path)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]
    gltf = pygltflib.GLTF2().load(str(path))
    assert gltf.extensionsRequired == [EXTENSION] and gltf.extensionsUsed == [EXTENSION]
    assert len(gltf.meshes) == tree.stats.types_used
    count = 0
    for node in gltf.nodes:
        attrs = node.extensions[EXTENSION]["attributes"]
        t, q, s = (_accessor(gltf, attrs[k]).astype(np.float64) for k in ("TRANSLATION", "ROTATION", "SCALE"))
        mesh_name = gltf.meshes[node.mesh].name
        rows = np.flatnonzero(tree.module == [m.name for m in modules.modules].index(mesh_name))
        assert len(rows) == len(t)
        tw, Rw, sw = decompose_similarity(tree.T_world_module[rows])
        # translation and scale exactly as written (float32), rotation up to float32 rounding
        np.testing.assert_array_equal(t, (tw @ C_YUP_ZUP.T).astype(np.float32))
        np.testing.assert_array_equal(s[:, 0], sw.astype(np.float32))
        assert np.allclose(np.linalg.norm(q, axis=1), 1, atol=1e-6)
        for i, r in enumerate(rows):
            np.testing.assert_allclose(_T_from_trs_yup(t[i], q[i], s[i]), tree.T_world_module[r], atol=2e-6 * 8)
            # a module vertex (and its base, the origin) lands on the same world point, seen Y up
            tip = modules.modules[tree.module[r]].vertices[-1]
            world = tree.T_world_module[r, :3, :3] @ tip + tree.T_world_module[r, :3, 3]
            R_y = quat_to_matrix(np.r_[q[i, 3], q[i, :3]])
            np.testing.assert_allclose(s[i, 0] * R_y @ zup_to_yup(tip) + t[i], zup_to_yup(world), atol=1e-4)
            np.testing.assert_allclose(t[i], zup_to_yup(tree.T_world_module[r, :3, 3]), atol=1e-5)
        count += len(t)
    assert count == tree.stats.modules_placed == len(tree.module)


def test_plain_nodes_glb_loads_fully_in_trimesh(tmp_path, grown):
    _, tree, inst = grown
    path = tmp_path / "plain.glb"
    write_instances(path, inst, plain=True)
    assert validate(path)["issues"]["numErrors"] == 0
    scene = trimesh.load(path)
    geoms = scene.dump()
    assert len(geoms) == len(tree.module)
    assert sum(len(g.faces) for g in geoms) == inst.triangles
    flat = zup_to_yup(flat_part(inst).positions)
    np.testing.assert_allclose(scene.bounds, [flat.min(0), flat.max(0)], atol=1e-4)
    ext = trimesh.load(write_and_path(tmp_path, inst))  # trimesh ignores the extension (FACTS.md)
    assert sum(len(g.faces) for g in ext.dump()) < inst.triangles


def write_and_path(tmp_path, inst):
    p = tmp_path / "ext.glb"
    write_instances(p, inst)
    return p


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_usd_point_instancer_reads_back(tmp_path, grown, suffix):
    from pxr import Usd, UsdGeom, UsdValidation

    _, tree, inst = grown
    path = tmp_path / f"tree{suffix}"
    write_instances(path, inst)
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Tree/Instancer"))
    t, R, s = decompose_similarity(tree.T_world_module)
    np.testing.assert_array_equal(np.asarray(pi.GetPositionsAttr().Get()), t.astype(np.float32))
    np.testing.assert_array_equal(np.asarray(pi.GetScalesAttr().Get())[:, 1], s.astype(np.float32))
    np.testing.assert_array_equal(np.asarray(pi.GetProtoIndicesAttr().Get()), inst.module)
    q = np.array([[x.GetReal(), *x.GetImaginary()] for x in pi.GetOrientationsfAttr().Get()])
    q_true = matrix_to_quat_xyzw(R)
    np.testing.assert_allclose(q, q_true[:, [3, 0, 1, 2]], atol=1e-7)  # float precision (orientationsf)
    assert not pi.GetOrientationsAttr().HasAuthoredValue()  # no half-precision copy
    xf = pi.ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default())
    got = np.array([np.array(m).T for m in xf])  # Gf row-vector matrices -> column convention
    np.testing.assert_allclose(got, tree.T_world_module, atol=1e-5)
    assert len(pi.GetPrototypesRel().GetTargets()) == tree.stats.types_used
    ctx = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    errors = [e for e in ctx.Validate(stage) if e.GetType() == UsdValidation.ValidationErrorType.Error]
    assert errors == []


def test_usd_validation_can_fail(tmp_path):
    """The validator used above does report a stage without up axis metadata."""
    from pxr import Usd, UsdGeom, UsdValidation

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.Xform.Define(stage, "/Bare")
    ctx = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    assert len(ctx.Validate(stage)) > 0


def test_same_seed_same_bytes(tmp_path, grown):
    modules, tree, inst = grown
    crown = crown_from_meshes([tetrahedron_mesh([0, 0, 4.5], 6.5)])
    again = from_modular_tree(
        grow_modular_tree(modules, crown, ModularTreeOptions(), np.random.default_rng(1)), modules)
    other = from_modular_tree(
        grow_modular_tree(modules, crown, ModularTreeOptions(), np.random.default_rng(2)), modules)
    for suffix in (".glb", ".usda", ".usdc"):
        a, b, c = (tmp_path / f"{n}{suffix}" for n in "abc")
        write_instances(a, inst)
        write_instances(b, again)
        write_instances(c, other)
        assert a.read_bytes() == b.read_bytes()
        assert a.read_bytes() != c.read_bytes()


def test_report_sizes_and_constraints(tmp_path, grown):
    _, tree, inst = grown
    size = write_instances(tmp_path / "t.glb", inst)
    flat = flat_size(inst, ".glb")
    rep = size_report(inst, size, flat)
    assert rep["modules_placed"] == len(tree.module) and rep["types_used"] == tree.stats.types_used
    assert rep["bytes"] == (tmp_path / "t.glb").stat().st_size
    # flat: every instance's vertices (positions + normals, 24 B) are stored again
    per_instance = sum(24 * len(inst.meshes[m].positions) for m in inst.module)
    assert flat > per_instance and rep["compression"] == pytest.approx(flat / size)
    # instanced: each used mesh once (positions + normals, uint16 indices) plus 40 B per instance (T, R, S)
    meshes = sum(24 * len(m.positions) + 6 * len(m.faces) for m in inst.meshes)
    data = (tmp_path / "t.glb").read_bytes()
    json_len = struct.unpack_from("<I", data, 12)[0]
    bin_len = struct.unpack_from("<I", data, 20 + json_len)[0]
    assert meshes + 40 * len(tree.module) <= bin_len <= meshes + 40 * len(tree.module) + 24 * len(inst.meshes)
    assert rep["compression"] > 5
    c = constraint_report(tree)
    assert c["violations"] == tree.stats.violations and sum(c["violations"].values()) == 0
    lo, hi = c["scale_range"]
    assert 0.5 - 1e-9 <= lo <= hi <= 2.0 + 1e-9
    assert 15 - 1e-6 <= c["branch_angle_deg_range"][0] <= c["branch_angle_deg_range"][1] <= 90 + 1e-6


def test_quaternions_and_bad_transforms():
    rng = np.random.default_rng(0)
    R = np.stack([axis_angle_matrix(rng.normal(size=3), a) for a in rng.uniform(0, 2 * np.pi, 200)])
    R[0] = np.diag([1.0, -1, -1])  # 180 degree turns take the other branches of Shepperd's method
    R[1] = np.diag([-1.0, 1, -1])
    R[2] = np.diag([-1.0, -1, 1])
    q = matrix_to_quat_xyzw(R)
    back = np.stack([quat_to_matrix(np.r_[x[3], x[:3]]) for x in q])
    np.testing.assert_allclose(back, R, atol=1e-12)
    with pytest.raises(ValidationError):
        decompose_similarity(make_transform(np.diag([1.0, 2.0, 1.0])))
    with pytest.raises(ValidationError):
        decompose_similarity(make_transform(np.diag([1.0, 1.0, -1.0])))
    with pytest.raises(ValidationError):
        instanced_glb_bytes([], [BARK], np.array([0]), np.eye(4)[None])
