"""Wavefront OBJ + MTL writer over plain arrays; textures are written beside the files.

OBJ has no frame of its own but most importers (Blender, Maya, three.js) read it as Y up, so the
writer converts the world's Z up with ``geometry.zup_to_yup`` unless ``y_up=False``. OBJ's texture
origin is the image's bottom-left, so v is flipped from the glTF convention of ``MeshPart.uv``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from arboretum_library.geometry import zup_to_yup

from .gltf import write_atomic
from .parts import Material, MeshPart


def _rows(fmt: str, arr: np.ndarray) -> str:
    """``fmt`` (one line, without newline) applied to every row of ``arr`` in one formatting call."""
    if not len(arr):
        return ""
    flat = arr.ravel().tolist()
    return ((fmt + "\n") * len(arr)) % tuple(flat)


def obj_text(meshes: Sequence[MeshPart], materials: Sequence[Material], mtl_name: str,
             y_up: bool = True) -> str:
    """The OBJ text: one group per mesh, ``usemtl`` its material, faces as v/vt/vn triples."""
    out = [f"# arboretum OBJ ({'Y' if y_up else 'Z'} up, metres)\n", f"mtllib {mtl_name}\n"]
    offset = 1
    for part in meshes:
        pos = zup_to_yup(part.positions) if y_up else part.positions
        n = len(pos)
        out.append(f"o {part.name}\n")
        out.append(_rows("v %.6f %.6f %.6f", pos))
        uv = part.uv if part.uv is not None else np.zeros((n, 2))
        out.append(_rows("vt %.6f %.6f", np.c_[uv[:, 0], 1.0 - uv[:, 1]]))
        if part.normals is not None:
            nrm = zup_to_yup(part.normals) if y_up else part.normals
            out.append(_rows("vn %.6f %.6f %.6f", nrm))
        if 0 <= part.material < len(materials):
            out.append(f"usemtl {materials[part.material].name}\n")
        f = part.faces + offset
        if part.normals is not None:
            trip = np.repeat(f, 3, axis=1)
            out.append(_rows("f %d/%d/%d %d/%d/%d %d/%d/%d", trip))
        else:
            out.append(_rows("f %d/%d %d/%d %d/%d", np.repeat(f, 2, axis=1)))
        offset += n
    return "".join(out)


def mtl_text(materials: Sequence[Material]) -> str:
    """The MTL text: diffuse colour, dissolve, and ``map_Kd`` / ``map_d`` for textured materials."""
    out = ["# arboretum MTL\n"]
    for m in materials:
        r, g, b, a = m.base_color
        out.append(f"newmtl {m.name}\nKd {r:.4f} {g:.4f} {b:.4f}\nKa 0 0 0\nKs 0 0 0\nd {a:.4f}\nillum 1\n")
        if m.texture_png is not None:
            tex = m.texture_name or f"{m.name}.png"
            out.append(f"map_Kd {tex}\n")
            if m.alpha_cutoff is not None:
                out.append(f"map_d {tex}\n")
    return "".join(out)


def write_obj(path: str | os.PathLike, meshes: Sequence[MeshPart], materials: Sequence[Material],
              y_up: bool = True) -> list[Path]:
    """Write PATH.obj, PATH.mtl and each material's PNG beside them; returns the files written."""
    path = Path(path)
    mtl = path.with_suffix(".mtl")
    written = []
    for m in materials:
        if m.texture_png is not None:
            tex = path.parent / (m.texture_name or f"{m.name}.png")
            write_atomic(tex, m.texture_png)
            written.append(tex)
    write_atomic(mtl, mtl_text(materials).encode())
    write_atomic(path, obj_text(meshes, materials, mtl.name, y_up).encode())
    return [path, mtl, *written]
