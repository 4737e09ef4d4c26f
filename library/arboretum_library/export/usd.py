"""USD export: module meshes as prototypes of a ``UsdGeom.PointInstancer`` (.usdc binary or .usda text).

The stage is Z up (``UsdGeom.SetStageUpAxis(stage, Z)``) with ``metersPerUnit = 1``, so world transforms
are written as they are: per instance ``positions`` (float3), ``orientationsf`` (float quaternions; full
float32 precision) and ``scales`` (float3, uniform), ``protoIndices`` (int). Points and positions are
float32, so a scene far from the origin (UTM, geocentric) is written relative to ``parts.local_origin``
and /Tree gets a double-precision ``xformOp:translate`` to it (none near the origin). ``pxr``
(usd-core) is imported inside the functions, so this module imports without it. Layout::

    /Tree                      Xform (default prim; translated to the local origin when far)
    /Tree/Instancer            PointInstancer
    /Tree/Instancer/Prototypes/<mesh name>   Mesh (one per prototype, not drawn on its own)
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from arboretum_library.errors import InputError, ValidationError

from .instanced import decompose_similarity, matrix_to_quat_xyzw
from .parts import MeshPart, local_origin

USD_FORMATS = (".usdc", ".usda", ".usd")


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError as exc:  # the 'export' extra is missing
        raise InputError("USD export needs the usd-core package (pip install usd-core)") from exc
    return Gf, Sdf, Usd, UsdGeom, Vt


def _prim_name(name: str, used: set[str]) -> str:
    """A valid, unique USD prim name for ``name``."""
    base = re.sub(r"[^A-Za-z0-9_]", "_", name) or "mesh"
    if base[0].isdigit():
        base = "m_" + base
    out, k = base, 1
    while out in used:
        out, k = f"{base}_{k}", k + 1
    used.add(out)
    return out


def _define_mesh(stage, path: str, part: MeshPart, origin: np.ndarray | None = None):
    """A Mesh prim at ``path`` with ``part``'s triangles, its points relative to ``origin`` (3,) if given."""
    _, _, _, UsdGeom, Vt = _pxr()
    mesh = UsdGeom.Mesh.Define(stage, path)
    pts = part.positions if origin is None or not origin.any() else part.positions - origin
    pts = np.asarray(pts, np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(part.faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(part.faces.astype(np.int32).reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if len(pts):
        mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([pts.min(0), pts.max(0)])))
    return mesh


def _new_stage(path: Path):
    """A new Z-up, metre stage at ``path`` with /Tree as default prim."""
    _, _, Usd, UsdGeom, _ = _pxr()
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Tree")
    stage.SetDefaultPrim(root.GetPrim())
    return stage


def _translate_root(stage, origin: np.ndarray) -> None:
    """Give /Tree a double-precision translate to ``origin`` (3,) (nothing when it is zero)."""
    if not origin.any():
        return
    Gf, _, _, UsdGeom, _ = _pxr()
    op = UsdGeom.Xform(stage.GetPrimAtPath("/Tree")).AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
    op.Set(Gf.Vec3d(*(float(x) for x in origin)))


def _save_atomic(path: str | os.PathLike, fill) -> int:
    """Create a stage in a temporary file of the same format, ``fill(stage)``, save, rename; returns bytes."""
    path = Path(path)
    if path.suffix.lower() not in USD_FORMATS:
        raise InputError(f"{path}: unknown USD format {path.suffix!r}; use .usdc, .usda or .usd")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    os.unlink(tmp)  # CreateNew refuses an existing layer
    try:
        stage = _new_stage(Path(tmp))
        fill(stage)
        stage.GetRootLayer().Save()
        del stage
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path.stat().st_size


def write_usd_instanced(path: str | os.PathLike, meshes: Sequence[MeshPart], mesh_index: np.ndarray,
                        T_world: np.ndarray) -> int:
    """Write a PointInstancer of ``meshes`` (prototypes) placed by ``T_world`` (K, 4, 4) world similarities.

    ``mesh_index`` (K,) picks each instance's prototype. Returns the file size in bytes.
    """
    mesh_index = np.asarray(mesh_index, np.int64).reshape(-1)
    T_world = np.asarray(T_world, np.float64).reshape(-1, 4, 4)
    if len(mesh_index) != len(T_world):
        raise ValidationError(f"instances: {len(mesh_index)} mesh indices but {len(T_world)} transforms")
    if len(mesh_index) and (mesh_index.min() < 0 or mesh_index.max() >= len(meshes)):
        raise ValidationError(f"instances: mesh indices must lie in 0..{len(meshes) - 1}")
    t, R, s = decompose_similarity(T_world)
    q = matrix_to_quat_xyzw(R)
    origin = local_origin(t)

    def fill(stage) -> None:
        Gf, Sdf, _, UsdGeom, Vt = _pxr()
        _translate_root(stage, origin)
        inst = UsdGeom.PointInstancer.Define(stage, "/Tree/Instancer")
        stage.DefinePrim("/Tree/Instancer/Prototypes", "Scope")
        used: set[str] = set()
        targets = []
        for part in meshes:
            p = f"/Tree/Instancer/Prototypes/{_prim_name(part.name, used)}"
            _define_mesh(stage, p, part)
            targets.append(Sdf.Path(p))
        inst.CreatePrototypesRel().SetTargets(targets)
        inst.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(mesh_index.astype(np.int32)))
        inst.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy((t - origin).astype(np.float32)))
        inst.CreateOrientationsfAttr(Vt.QuatfArray([Gf.Quatf(float(w), float(x), float(y), float(z))
                                                    for x, y, z, w in q]))
        inst.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(np.repeat(s[:, None], 3, 1).astype(np.float32)))

    return _save_atomic(path, fill)


def write_usd_mesh(path: str | os.PathLike, part: MeshPart) -> int:
    """Write one flat mesh (world frame, Z up) as /Tree/Mesh; returns the file size in bytes."""
    origin = local_origin(part.positions)

    def fill(stage) -> None:
        _translate_root(stage, origin)
        _define_mesh(stage, "/Tree/Mesh", part, origin)

    return _save_atomic(path, fill)


def read_usd_instancer(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """World positions (K, 3), orientations wxyz (K, 4), scales (K, 3), protoIndices (K,) of
    /Tree/Instancer (positions include /Tree's translate; any rotation or scale of /Tree is ignored)."""
    _, _, Usd, UsdGeom, _ = _pxr()
    stage = Usd.Stage.Open(str(path))
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Tree/Instancer"))
    quats = inst.GetOrientationsfAttr().Get()
    wxyz = np.array([[q.GetReal(), *q.GetImaginary()] for q in quats], np.float64).reshape(-1, 4)
    shift = np.array(inst.ComputeLocalToWorldTransform(Usd.TimeCode.Default()).ExtractTranslation())
    return {
        "positions": np.asarray(inst.GetPositionsAttr().Get(), np.float64).reshape(-1, 3) + shift,
        "orientations": wxyz,
        "scales": np.asarray(inst.GetScalesAttr().Get(), np.float64).reshape(-1, 3),
        "protoIndices": np.asarray(inst.GetProtoIndicesAttr().Get(), np.int64),
    }
