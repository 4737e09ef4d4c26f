"""The up axis of a mesh file read into the world frame (Z up): ``--up auto|y|z`` of ``render`` and
``modules --crown``.

glTF is Y up by definition. OBJ and PLY do not say: Arboretum's OBJ names its axis on its first line
(``obj.obj_up_axis``), and a PLY is Z up as Arboretum, scanners and photogrammetry tools write it. For
a file without Arboretum's header, ``auto`` keeps the format's usual axis (OBJ Y, as Blender and Maya
write it; PLY Z) unless the vertices stand along the other one surely: the same test as a point
cloud's ``--up auto`` (``pointio_spatial.guess_up_axis``, confidence >= 0.75), so a tree exported Z up
from 3ds Max or a GIS tool is read upright. An explicit ``y`` or ``z`` always wins.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.pointio_spatial import guess_up_axis

from .obj import obj_header_axis

UP_CHOICES = ("auto", "y", "z")
"""The values of ``--up`` for mesh inputs."""
SURE = 0.75
"""``auto`` leaves a format's usual axis only when ``guess_up_axis`` is this sure of the other (as
``pointio.AUTO_Y_CONFIDENCE`` for point clouds)."""


def mesh_up_axis(path: str | os.PathLike, vertices: np.ndarray, up: str = "auto", what: str = "INPUT") -> str:
    """'y' or 'z': the up axis of the mesh file ``path`` whose vertices (V, 3) are ``vertices`` as stored.

    ``up`` is 'auto', 'y' or 'z' (see the module doc); 'y' or 'z' for a glTF file other than its own
    'y' is an ``InputError`` naming ``what``.
    """
    if up not in UP_CHOICES:
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
    if suffix == ".obj" and (header := obj_header_axis(path)) is not None:
        return header
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    if len(v) < 8 or not np.isfinite(v).all():
        return usual
    guess, confidence = guess_up_axis(v)
    return guess if guess != usual and confidence >= SURE else usual
