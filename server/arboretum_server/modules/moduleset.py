"""Module sets: branch and trunk meshes with their skeletons, normalised base at origin pointing +Z."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from arboretum_library.errors import InputError

from .skeleton import ModuleSkeleton, extract_skeleton


@dataclass(frozen=True)
class Module:
    name: str
    """File stem, e.g. 'branch_03_fork'; names starting with 'trunk' are trunks."""
    vertices: np.ndarray
    """(V, 3) float64 module frame: base at the origin, base direction +Z, metres."""
    faces: np.ndarray
    """(F, 3) int32 triangles."""
    skeleton: ModuleSkeleton
    """Skeleton curves in the module frame."""

    @property
    def is_trunk(self) -> bool:
        return self.name.startswith("trunk")

    @property
    def size(self) -> float:
        """size(M) of Eq. 1: largest distance from the base to a skeleton point (metres, scale 1)."""
        return float(np.linalg.norm(self.skeleton.points, axis=1).max())


@dataclass(frozen=True)
class ModuleSet:
    modules: tuple[Module, ...]
    """All modules; indices into this tuple identify module types in a grown tree."""

    @property
    def branch_indices(self) -> np.ndarray:
        return np.array([i for i, m in enumerate(self.modules) if not m.is_trunk], dtype=np.int64)

    @property
    def trunk_indices(self) -> np.ndarray:
        return np.array([i for i, m in enumerate(self.modules) if m.is_trunk], dtype=np.int64)

    def subset(self, names: list[str]) -> ModuleSet:
        """The modules named in ``names`` (in that order)."""
        by_name = {m.name: m for m in self.modules}
        missing = [n for n in names if n not in by_name]
        if missing:
            raise InputError(f"module set: no module named {missing[0]!r}")
        return ModuleSet(tuple(by_name[n] for n in names))


def rotation_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3x3 rotation taking unit vector ``a`` (3,) to unit vector ``b`` (3,) by the shortest arc."""
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1 + 1e-12:
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def make_module(name: str, vertices: np.ndarray, faces: np.ndarray) -> Module:
    """Extract the skeleton of a mesh (base on its lowest plane) and normalise base -> origin, +Z."""
    sk = extract_skeleton(vertices, faces)
    R = rotation_to(sk.base_direction, np.array([0.0, 0.0, 1.0]))
    base = sk.base.copy()

    def move(p: np.ndarray) -> np.ndarray:
        return (np.asarray(p) - base) @ R.T

    sk = replace(
        sk,
        points=move(sk.points),
        tangent=sk.tangent @ R.T,
        base=np.zeros(3),
        base_direction=np.array([0.0, 0.0, 1.0]),
    )
    return Module(name, move(vertices), np.asarray(faces, dtype=np.int32), sk)


def load_module_set(folder: str | Path, up: str = "auto") -> ModuleSet:
    """All ``*.obj``, ``*.glb`` and ``*.gltf`` files of ``folder`` as a module set (sorted by name).

    Pieces (branch segments, leaf cards) are never read by their shape (``mesh_up``'s guess): a file
    with Arboretum's header is read by it, any other by ``up`` ('y' or 'z', ``modules --modules-up``;
    'auto': the format's usual axis, OBJ Y up)."""
    from .meshio import load_mesh

    folder = Path(folder)
    files = sorted(p for p in folder.glob("*") if p.suffix.lower() in (".obj", ".glb", ".gltf"))
    if not files:
        raise InputError(f"module folder {folder}: no .obj/.glb/.gltf files")
    key = _folder_key(folder, files, up)
    if key in _LOADED:
        return _LOADED[key]
    modules = tuple(_read_only(make_module(p.stem, *load_mesh(p, "module mesh", headerless=up))) for p in files)
    if not any(not m.is_trunk for m in modules):
        raise InputError(f"module folder {folder}: no branch modules (only trunk_* files)")
    while len(_LOADED) >= LOADED_SETS:
        _LOADED.pop(next(iter(_LOADED)))
    _LOADED[key] = ModuleSet(modules)
    return _LOADED[key]


LOADED_SETS = 4
"""How many module sets ``load_module_set`` keeps read (the oldest read is dropped first)."""

_LOADED: dict[tuple, ModuleSet] = {}
"""Module sets already read, by ``_folder_key``: a server answering ``modules`` requests, or one process
growing many trees, extracts each skeleton once (0.3-0.4 s CPU for the bundled 25 modules)."""


def _folder_key(folder: Path, files: list[Path], up: str) -> tuple:
    """What a read of ``files`` depends on: the folder, ``up`` and each file's name, size and change time
    (a file rewritten in place is read again)."""
    stats = tuple((p.name, st.st_size, st.st_mtime_ns) for p in files for st in [p.stat()])
    return str(folder.resolve()), up, stats


def _read_only(module: Module) -> Module:
    """``module`` with its arrays and its skeleton's made read-only (a kept set is shared by every caller)."""
    sk = module.skeleton
    for a in (module.vertices, module.faces, sk.points, sk.radius, sk.tangent, sk.spline, sk.spline_parent,
              sk.base, sk.base_direction, sk.tips):
        a.flags.writeable = False
    return module


def save_module_set(modules: ModuleSet, folder: str | Path, note: str = "") -> list[Path]:
    """Write every module as ``folder/NAME.obj`` (Z up, metres); returns the paths."""
    from .meshio import save_obj

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for m in modules.modules:
        save_obj(
            folder / f"{m.name}.obj",
            m.vertices,
            m.faces,
            comment=f"Arboretum module {m.name}\n{note}",
        )
        out.append(folder / f"{m.name}.obj")
    return out
