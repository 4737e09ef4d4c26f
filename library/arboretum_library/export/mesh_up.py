"""The up axis of a mesh file read into the world frame (Z up): ``--up auto|y|z`` of ``render`` and
``modules --crown``, and ``modules --modules-up`` for module pieces.

glTF is Y up by definition. OBJ and PLY do not say: Arboretum's OBJ names its axis on its first line
(``obj.obj_header_axis``) and its PLY in a header comment (``ply_header_axis``), and a PLY is Z up as
Arboretum, scanners and photogrammetry tools write it. For a file without Arboretum's header,
``auto`` keeps the format's usual axis (OBJ Y, as Blender and Maya write it; PLY Z) unless the
vertices stand along the other one surely: the same test as a point cloud's ``--up auto``
(``pointio_up.guess_up_axis``, confidence >= 0.75), so a tree exported Z up from 3ds Max or a GIS
tool is read upright. An explicit ``y`` or ``z`` always wins. Module pieces are never guessed.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.pointio import AUTO_Y_CONFIDENCE, UP_CHOICES
from arboretum_library.pointio_up import guess_up_axis

from .obj import obj_header_axis

# ``--up`` takes the point clouds' values (``pointio.UP_CHOICES``); ``auto`` leaves a format's usual axis
# only when ``guess_up_axis`` is as sure of the other as a point cloud's ``--up auto`` must be
# (``pointio.AUTO_Y_CONFIDENCE``).
_PLY_HEADER = re.compile(r"comment arboretum\b.*\b([YZ]) up\b", re.IGNORECASE)


def ply_header_axis(path: str | os.PathLike) -> str | None:
    """'y' or 'z' when the PLY at ``path`` carries Arboretum's header comment (``export.ply`` writes
    ``comment arboretum, Z up, metres``), else None. Reads the header only (at most 64 KiB)."""
    with open(path, "rb") as f:
        head = f.read(65536)
    for line in head.split(b"end_header", 1)[0].decode("latin-1").splitlines():
        if (found := _PLY_HEADER.match(line.strip())) is not None:
            return found.group(1).lower()
    return None


def header_axis(path: str | os.PathLike) -> str | None:
    """'y' or 'z' when the .obj or .ply at ``path`` carries Arboretum's header, else None."""
    suffix = Path(path).suffix.lower()
    return obj_header_axis(path) if suffix == ".obj" else ply_header_axis(path) if suffix == ".ply" else None


def mesh_up_axis(path: str | os.PathLike, vertices: np.ndarray, up: str = "auto", what: str = "INPUT",
                 headerless: str | None = None) -> str:
    """'y' or 'z': the up axis of the mesh file ``path`` whose vertices (V, 3) are ``vertices`` as stored.

    ``up`` is 'auto', 'y' or 'z' (see the module doc); 'y' or 'z' for a glTF file other than its own
    'y' is an ``InputError`` naming ``what``. ``headerless`` ('auto', 'y' or 'z'; module pieces, whose
    shape says nothing of their up axis): Arboretum's header decides, else this axis ('auto': the
    format's usual one), never the vertices.
    """
    if up not in UP_CHOICES or headerless not in (None, *UP_CHOICES):
        raise InputError(f"--up must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".glb", ".gltf"):
        if up == "z":
            raise InputError(f"{what} {path}: glTF is Y up by definition; --up z applies to .obj and .ply")
        return "y"
    if up != "auto":
        return up
    usual = "y" if suffix == ".obj" else "z"
    header = header_axis(path)
    if header is not None:
        return header
    if headerless is not None:
        return usual if headerless == "auto" else headerless
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    if len(v) < 8 or not np.isfinite(v).all():
        return usual
    axis, confidence = guess_up_axis(v)
    return axis if axis != usual and confidence >= AUTO_Y_CONFIDENCE else usual
