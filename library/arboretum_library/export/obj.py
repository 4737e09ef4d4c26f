"""Wavefront OBJ + MTL writer over plain arrays, with the textures written beside the files.

OBJ has no frame of its own but most importers (Blender, Maya, three.js) read it as Y up, so the
writer converts the world's Z up with ``geometry.zup_to_yup`` unless ``y_up=False``; the first line
says which (``# arboretum OBJ (Y up, metres)``) and ``obj_up_axis`` reads it back. OBJ's texture
origin is the image's bottom-left, so v is flipped from the glTF convention of ``MeshPart.uv``.

The sidecars are named after the OBJ's stem (``tree.obj`` -> ``tree.mtl``, ``tree_bark.png``,
``tree_leaf.png``) so two exports in one folder do not overwrite each other. Existing files that
Arboretum did not write are refused, and all files go to temporary names first and are renamed only
once every one is written, with Ctrl-C held back until the last rename (``atomic.write_files_atomic``), so
an interrupt leaves the previous set or the new one, never a mix. The .mtl, which records the textures
Arboretum owns, is renamed first and the .obj last.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from arboretum_library.atomic import write_files_atomic
from arboretum_library.errors import InputError
from arboretum_library.geometry import zup_to_yup

from .parts import Material, MeshPart

MTL_HEADER = "# arboretum MTL\n"
_HEADER = re.compile(r"# arboretum OBJ \(([YZ]) up\b")


def obj_header(y_up: bool = True) -> str:
    """The first line (without newline) of the OBJ files Arboretum writes, naming the up axis that
    ``obj_up_axis`` reads back: '# arboretum OBJ (Y up, metres)' or '... (Z up, metres)'."""
    return f"# arboretum OBJ ({'Y' if y_up else 'Z'} up, metres)"


def _rows(fmt: str, arr: np.ndarray) -> str:
    """``fmt`` (one line, without newline) applied to every row of ``arr`` in one formatting call."""
    if not len(arr):
        return ""
    flat = arr.ravel().tolist()
    return ((fmt + "\n") * len(arr)) % tuple(flat)


def obj_text(meshes: Sequence[MeshPart], materials: Sequence[Material], mtl_name: str,
             y_up: bool = True) -> str:
    """The OBJ text: one group per mesh, ``usemtl`` its material, faces as v/vt/vn triples.

    Positions are written with 6 decimals (1 µm at any magnitude: 16 digits at 1e7 m)."""
    out = [obj_header(y_up) + "\n", f"mtllib {mtl_name}\n"]
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


def texture_file_name(stem: str, material: Material) -> str:
    """The PNG file name of a textured ``material`` beside ``stem``.obj: 'tree_bark.png'."""
    return f"{stem}_{material.texture_name or material.name + '.png'}"


def mtl_text(materials: Sequence[Material], stem: str = "") -> str:
    """The MTL text: diffuse colour, dissolve, and ``map_Kd`` / ``map_d`` for textured materials
    (texture files named by ``texture_file_name(stem, ...)``, or the material's own name without a stem)."""
    out = [MTL_HEADER]
    for m in materials:
        r, g, b, a = m.base_color
        out.append(f"newmtl {m.name}\nKd {r:.4f} {g:.4f} {b:.4f}\nKa 0 0 0\nKs 0 0 0\nd {a:.4f}\nillum 1\n")
        if m.texture_png is not None:
            tex = texture_file_name(stem, m) if stem else (m.texture_name or f"{m.name}.png")
            out.append(f"map_Kd {tex}\n")
            if m.alpha_cutoff is not None:
                out.append(f"map_d {tex}\n")
    return "".join(out)


def obj_up_axis(path: str | os.PathLike) -> str:
    """'y' or 'z': the up axis of the OBJ at ``path`` by its header (``obj_header_axis``), else Y up, as
    Blender, Maya and most OBJ exporters write it (``export.mesh_up.mesh_up_axis`` also looks at the
    vertices of a file without our header)."""
    return obj_header_axis(path) or "y"


def obj_header_axis(path: str | os.PathLike) -> str | None:
    """'y' or 'z' when the OBJ at ``path`` starts with Arboretum's header, else None.

    Only Arboretum's own first line counts: ``# arboretum OBJ (Y up`` / ``(Z up`` (this writer and
    ``save_obj``), and ``# Arboretum module`` (module files from ``save_obj`` before it wrote that line,
    Z up), whatever other files' comments say ("axes converted from Z-up to Y-up" is no header of ours)."""
    with open(path, encoding="utf-8", errors="replace") as f:
        first = f.readline().strip()
    if (found := _HEADER.match(first)) is not None:
        return found.group(1).lower()
    return "z" if first.startswith("# Arboretum module") else None


def _ours(path: Path, data: bytes, owned: set[str]) -> bool:
    """True when ``path`` may be replaced: absent, named by our previous MTL, or identical."""
    if not path.exists() or path.name in owned:
        return True
    return path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data


def _previous_sidecars(mtl: Path) -> set[str]:
    """Texture names referenced by an Arboretum MTL at ``mtl``; InputError when a foreign one is there."""
    if not mtl.exists():
        return set()
    try:
        text = mtl.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        text = ""
    if not text.startswith(MTL_HEADER):
        raise InputError(f"{mtl}: exists and was not written by Arboretum; move it away or choose "
                         f"another output name")
    return {line.split(maxsplit=1)[1].strip() for line in text.splitlines()
            if line.startswith(("map_Kd ", "map_d "))}


def check_sidecars(path: str | os.PathLike, materials: Sequence[Material]) -> list[tuple[Path, bytes]]:
    """The (file, PNG bytes) textures ``write_obj(path, ...)`` writes beside ``path``; InputError when
    PATH.mtl or one of them exists and was not written by Arboretum (a CLI may call this before long
    work to fail early)."""
    path = Path(path)
    owned = _previous_sidecars(path.with_suffix(".mtl"))
    files: list[tuple[Path, bytes]] = []
    for m in materials:
        if m.texture_png is not None:
            tex = path.parent / texture_file_name(path.stem, m)
            if not _ours(tex, m.texture_png, owned):
                raise InputError(f"{tex}: exists and was not written by Arboretum for {path.name}; "
                                 f"move it away or choose another output name")
            files.append((tex, m.texture_png))
    return files


def write_obj(path: str | os.PathLike, meshes: Sequence[MeshPart], materials: Sequence[Material],
              y_up: bool = True) -> list[Path]:
    """Write PATH.obj, PATH.mtl and each textured material's PNG as PATH-stem_NAME.png beside them;
    returns the files written (the .obj first). InputError, before anything is written, when one of
    the sidecars exists and was not written by Arboretum."""
    path = Path(path)
    mtl = path.with_suffix(".mtl")
    textures = check_sidecars(path, materials)
    files = [(mtl, mtl_text(materials, path.stem).encode()), *textures,
             (path, obj_text(meshes, materials, mtl.name, y_up).encode())]
    write_files_atomic(files)
    return [path, mtl, *(p for p, _ in textures)]
