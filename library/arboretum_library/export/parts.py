"""What the writers take: triangle meshes as plain arrays, materials, and nodes that place meshes.

Everything is in the world frame (right-handed, Z up, metres); each writer converts to its format's
frame (glTF: Y up). Formats store positions as float32, which at UTM coordinates (5.4e6 m) resolves
only 0.5 m: the writers store them relative to ``local_origin`` and put that offset, in float64, on a
root node (glTF) or prim (USD).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arboretum_library.errors import ValidationError

FAR = 128.0
"""A scene whose bounding-box centre lies farther than this (m, in any coordinate) from the world origin
is written relative to ``local_origin``; nearer ones as they are (float32 resolves 8 µm at 128 m)."""


def local_origin(points: np.ndarray) -> np.ndarray:
    """(3,) float64, metres: where a writer puts its scene's origin for world ``points`` (N, 3) (Z up).

    The centre of their bounding box rounded to whole metres, or (0, 0, 0) when that centre is within
    ``FAR`` of the world origin (or there are no points).
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if not len(p):
        return np.zeros(3)
    centre = (p.min(0) + p.max(0)) / 2
    return np.round(centre) + 0.0 if np.abs(centre).max() > FAR else np.zeros(3)


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One triangle mesh with one material."""

    name: str
    positions: np.ndarray
    """(V, 3) float, metres, world frame (Z up)."""
    faces: np.ndarray
    """(F, 3) int: counter-clockwise (outward) triangles into ``positions``."""
    normals: np.ndarray | None = None
    """(V, 3) float unit vertex normals, or None."""
    uv: np.ndarray | None = None
    """(V, 2) float texture coordinates (glTF convention: v = 0 at the image's top), or None."""
    material: int = 0
    """Index into the scene's materials."""

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions, np.float64)
        faces = np.asarray(self.faces, np.int64)
        if pos.ndim != 2 or pos.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            raise ValidationError(f"MeshPart {self.name!r}: positions must be (V, 3) and faces (F, 3)")
        if faces.size and (faces.min() < 0 or faces.max() >= len(pos)):
            raise ValidationError(f"MeshPart {self.name!r}: face indices must lie in 0..{len(pos) - 1}")
        for name, width in (("normals", 3), ("uv", 2)):
            arr = getattr(self, name)
            if arr is not None and np.asarray(arr).shape != (len(pos), width):
                raise ValidationError(f"MeshPart {self.name!r}: {name} must be ({len(pos)}, {width})")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "faces", faces)


@dataclass(frozen=True)
class Material:
    """A PBR metallic-roughness material, optionally textured."""

    name: str
    base_color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    """Linear RGBA factor."""
    texture_png: bytes | None = None
    """PNG bytes of the base colour texture (with alpha for cut-out leaves), or None."""
    texture_name: str = ""
    """File name for formats that keep textures beside the model (OBJ), e.g. 'bark.png'."""
    alpha_cutoff: float | None = None
    """Alpha below this is cut out (glTF alphaMode MASK); None for opaque."""
    double_sided: bool = False
    roughness: float = 0.9
    metallic: float = 0.0


@dataclass(frozen=True, eq=False)
class Node:
    """A placement of a mesh: plain nodes sharing one mesh are how instances survive every importer."""

    mesh: int
    """Index into the scene's meshes."""
    T_world_node: np.ndarray = field(default_factory=lambda: np.eye(4))
    """(4, 4) float64: rigid or similarity transform in the world frame (Z up)."""
    name: str = ""
