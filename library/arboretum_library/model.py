"""The Hierarchical Branch-Lobe (HBL) data model: plain, frozen, validated records over numpy arrays.

VRTree section 3.2: a tree is main branches (its topology and primary shape), secondary branches (from
the main branches out to the crown) and lobes (closed volumes in which twigs and leaves grow, each fed by
one secondary branch). An ``Example`` is one main branch with its secondary branches and lobes; an
``Assembly`` (``arboretum_library.assembly``) places examples (and sketched ones) to make a new tree.

Conventions: right-handed, Z up, metres; float64 arrays in records (float32 only on the wire and on the
GPU); int32 indices. Every array is copied on construction and made read-only, so a record never changes
under its holder. Construction validates shapes, finiteness and index ranges, and a failure raises
``ValidationError`` naming the field.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import ValidationError

F64 = NDArray[np.float64]
I32 = NDArray[np.int32]
U8 = NDArray[np.uint8]

WOOD = 0
"""Label of a wood (branch) point in ``HBL.labels``."""
LEAF = 1
"""Label of a leaf (foliage) point in ``HBL.labels``."""


class Level(IntEnum):
    """Level of a branch in the hierarchy (VRTree section 3.2)."""

    MAIN = 0
    SECONDARY = 1
    TWIG = 2


def frozen_array(owner: object, name: str, value: Any, dtype: type, shape: tuple) -> np.ndarray:
    """Copy ``value`` to a read-only array of ``dtype`` and check its shape (None = any length)."""
    where = f"{type(owner).__name__}.{name}"
    try:
        arr = np.array(value, dtype=dtype, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{where}: cannot convert to {np.dtype(dtype).name}: {exc}") from None
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        dims = ["N" if s is None else str(s) for s in shape]
        want = f"({dims[0]},)" if len(dims) == 1 else "(" + ", ".join(dims) + ")"
        raise ValidationError(f"{where}: expected shape {want}, got {arr.shape}")
    if arr.dtype.kind == "f" and arr.size and not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr)).sum())
        raise ValidationError(f"{where}: {bad} value(s) are NaN or infinite")
    arr.flags.writeable = False
    object.__setattr__(owner, name, arr)
    return arr


def _check_index(owner: object, name: str, value: int, upper: int, allow_none: bool = True) -> None:
    low = -1 if allow_none else 0
    if not low <= value < upper:
        rng = f"-1 (none) or 0..{upper - 1}" if allow_none else f"0..{upper - 1}"
        raise ValidationError(f"{type(owner).__name__}.{name}: {value} is out of range ({rng})")


@dataclass(frozen=True, eq=False)
class Branch:
    """A branch as a polyline with a radius per vertex."""

    points: F64
    """(N, 3) float64, metres: vertices from the attachment end to the tip. N >= 2."""
    radii: F64
    """(N,) float64, metres, > 0: radius at each vertex."""
    parent: int = -1
    """Index of the parent branch in the owning structure's ``branches``; -1 for none (a root)."""
    parent_vertex: int = -1
    """Vertex index on the parent where this branch attaches; -1 when ``parent`` is -1."""
    level: Level = Level.MAIN
    """MAIN, SECONDARY or TWIG."""

    def __post_init__(self) -> None:
        pts = frozen_array(self, "points", self.points, np.float64, (None, 3))
        if len(pts) < 2:
            raise ValidationError(f"Branch.points: a branch needs at least 2 vertices, got {len(pts)}")
        rad = frozen_array(self, "radii", self.radii, np.float64, (len(pts),))
        if (rad <= 0).any():
            raise ValidationError(f"Branch.radii: {int((rad <= 0).sum())} radius(es) are not > 0")
        object.__setattr__(self, "level", Level(self.level))
        if (self.parent < 0) != (self.parent_vertex < 0):
            raise ValidationError("Branch.parent_vertex: must be -1 exactly when parent is -1")

    @property
    def length(self) -> float:
        """Arc length in metres."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


@dataclass(frozen=True, eq=False)
class Lobe:
    """A closed volume in which twigs and leaves grow, fed by one secondary branch."""

    points: F64
    """(M, 3) float64, metres: the foliage points clustered into this lobe (may be empty if sketched)."""
    hull_vertices: F64
    """(V, 3) float64, metres: vertices of the closed hull (alpha shape or convex fallback). V >= 4."""
    hull_faces: I32
    """(F, 3) int32: outward-facing triangles into ``hull_vertices``. F >= 4."""
    centre: F64
    """(3,) float64, metres: the lobe centre (k-means centre of its points, or hull centroid)."""
    branch: int = -1
    """Index of the feeding secondary branch in the owning structure's ``branches``; -1 for none."""

    def __post_init__(self) -> None:
        frozen_array(self, "points", self.points, np.float64, (None, 3))
        verts = frozen_array(self, "hull_vertices", self.hull_vertices, np.float64, (None, 3))
        faces = frozen_array(self, "hull_faces", self.hull_faces, np.int32, (None, 3))
        frozen_array(self, "centre", self.centre, np.float64, (3,))
        if len(verts) < 4 or len(faces) < 4:
            raise ValidationError(
                f"Lobe.hull_faces: a closed hull needs >= 4 vertices and faces, got {len(verts)} and {len(faces)}"
            )
        if faces.min() < 0 or faces.max() >= len(verts):
            raise ValidationError(f"Lobe.hull_faces: indices must lie in 0..{len(verts) - 1}")


_HBL_POSITIONS = ("root", "points")
_BRANCH_POSITIONS = ("points",)
_LOBE_POSITIONS = ("points", "hull_vertices", "centre")
"""The position fields (metres, frame of the structure) of an HBL and of its branches and lobes: the one
list ``HBL.arrays`` walks and ``HBL.map_positions`` maps."""


@dataclass(frozen=True, eq=False)
class HBL:
    """A Hierarchical Branch-Lobe structure: a whole tree, or the content of one example.

    Branches are in topological order: a branch's parent comes before it.
    """

    root: F64
    """(3,) float64, metres: the trunk base."""
    branches: tuple[Branch, ...]
    """Main, secondary (and twig) branches, parents first."""
    lobes: tuple[Lobe, ...] = ()
    """Lobes, each naming its feeding branch."""
    points: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    """(N, 3) float64, metres: the source points this structure was decomposed from (may be empty)."""
    labels: U8 = field(default_factory=lambda: np.zeros(0, np.uint8))
    """(N,) uint8: WOOD (0) or LEAF (1) for each source point."""

    def __post_init__(self) -> None:
        frozen_array(self, "root", self.root, np.float64, (3,))
        pts = frozen_array(self, "points", self.points, np.float64, (None, 3))
        labels = frozen_array(self, "labels", self.labels, np.uint8, (len(pts),))
        if labels.size and labels.max() > LEAF:
            raise ValidationError("HBL.labels: values must be 0 (wood) or 1 (leaf)")
        object.__setattr__(self, "branches", tuple(self.branches))
        object.__setattr__(self, "lobes", tuple(self.lobes))
        for i, b in enumerate(self.branches):
            if b.parent >= i:
                raise ValidationError(f"HBL.branches[{i}].parent: {b.parent} must come before the branch")
            if b.parent >= 0:
                parent = self.branches[b.parent]
                _check_index(b, "parent_vertex", b.parent_vertex, len(parent.points), False)
                if parent.level > b.level:
                    raise ValidationError(
                        f"HBL.branches[{i}].level: a {b.level.name} branch cannot grow from a {parent.level.name} one"
                    )
        for j, lobe in enumerate(self.lobes):
            if lobe.branch >= len(self.branches):
                raise ValidationError(f"HBL.lobes[{j}].branch: {lobe.branch} is out of range")

    def arrays(self) -> Iterator[tuple[str, np.ndarray]]:
        """(field path, array) of every coordinate and radius the structure holds, e.g.
        ``("lobes[2].hull_vertices", (V, 3) array)``: the root, source points, branch points and radii,
        lobe points, hull vertices and centres (metres). All but the radii are what ``map_positions``
        maps."""
        for name in _HBL_POSITIONS:
            yield name, getattr(self, name)
        for i, b in enumerate(self.branches):
            for name in (*_BRANCH_POSITIONS, "radii"):
                yield f"branches[{i}].{name}", getattr(b, name)
        for j, lb in enumerate(self.lobes):
            for name in _LOBE_POSITIONS:
                yield f"lobes[{j}].{name}", getattr(lb, name)

    def map_positions(self, fn: Callable[[np.ndarray], Any]) -> HBL:
        """A new (validated) HBL with every position array ``a`` of ``arrays()`` (all but radii) replaced by
        ``fn(a)`` (same shape), e.g. ``lambda a: a + offset`` to move it; radii, topology and labels kept."""
        def mapped(rec, names: tuple[str, ...]):
            return replace(rec, **{n: fn(getattr(rec, n)) for n in names})

        return replace(self, branches=tuple(mapped(b, _BRANCH_POSITIONS) for b in self.branches),
                       lobes=tuple(mapped(lb, _LOBE_POSITIONS) for lb in self.lobes),
                       **{n: fn(getattr(self, n)) for n in _HBL_POSITIONS})

    @functools.cached_property
    def extent(self) -> float:
        """Largest magnitude, metres, of any coordinate or radius in ``arrays()`` (computed once: the
        record never changes)."""
        return max((float(np.abs(a).max()) for _, a in self.arrays() if a.size), default=0.0)

    def by_level(self, level: Level) -> list[int]:
        """Indices of the branches at ``level``."""
        return [i for i, b in enumerate(self.branches) if b.level == level]

    @property
    def height(self) -> float:
        """Height in metres of everything the structure holds above its root."""
        zs = [b.points[:, 2] for b in self.branches] + [lb.hull_vertices[:, 2] for lb in self.lobes]
        return float(np.concatenate(zs).max() - self.root[2]) if zs else 0.0


@dataclass(frozen=True)
class Provenance:
    """Where an example came from."""

    source: str
    """The source scan's file name, or ``synthetic:MODEL:SPECIES:SEED``, or ``sketch``."""
    source_sha256: str = ""
    """Hex SHA-256 of the source file's bytes, or of the points of a service ``library.import`` ('' for
    neither)."""
    species: str = "unknown"
    """Species name in lower case."""
    parameters: Mapping[str, Any] = field(default_factory=dict)
    """The decomposition parameters used (JSON-serialisable)."""


@dataclass(frozen=True)
class Descriptors:
    """Numbers that classify an example (VRTree Fig. 6), computed by ``descriptors.describe``."""

    curvature: float
    """How far the main branch bows from its chord, as the angle in radians of the circular arc that
    bows as far (``descriptors.polyline_curvature``): 0 straight, pi/2 a quarter circle."""
    lobe_count: int
    """Number of lobes."""
    length: float
    """Arc length of the main branch, metres."""
    spread: float
    """Mean distance of lobe centres from the main branch, metres."""
    height: float
    """Vertical extent of branches and lobes above the root, metres."""


@dataclass(frozen=True, eq=False)
class Example:
    """One library example: a main branch (``structure.branches[0]``), its secondary branches, lobes."""

    id: str
    """Library-unique identifier (letters, digits, '-' and '_')."""
    structure: HBL
    """The example's HBL; exactly one MAIN branch, at index 0, with parent -1."""
    provenance: Provenance
    descriptors: Descriptors
    tags: tuple[str, ...] = ()
    """Keywords such as dense, sparse, straight, curved (lower case)."""

    def __post_init__(self) -> None:
        if not self.id or not all(c.isalnum() or c in "-_" for c in self.id) or len(self.id) > 128:
            raise ValidationError(f"Example.id: {self.id!r} must be 1-128 letters, digits, '-' or '_'")
        mains = self.structure.by_level(Level.MAIN)
        if mains != [0] or self.structure.branches[0].parent != -1:
            raise ValidationError(f"Example.structure: needs exactly one MAIN root branch at index 0, got {mains}")
        object.__setattr__(self, "tags", tuple(sorted({t.lower() for t in self.tags})))
