"""The Hierarchical Branch-Lobe (HBL) data model: plain, frozen, validated records over numpy arrays.

VRTree section 3.2: a tree is main branches (its topology and primary shape), secondary branches (from
the main branches out to the crown) and lobes (closed volumes in which twigs and leaves grow, each fed by
one secondary branch). An ``Example`` is one main branch with its secondary branches and lobes; an
``Assembly`` places examples (and sketched ones) to make a new tree.

Conventions: right-handed, Z up, metres; float64 arrays in records (float32 only on the wire and on the
GPU); int32 indices. Every array is copied on construction and made read-only, so a record never changes
under its holder. Construction validates shapes, finiteness and index ranges, and a failure raises
``ValidationError`` naming the field.
"""

from __future__ import annotations

import functools
import math
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

    def arrays(self, radii: bool = True) -> Iterator[tuple[str, np.ndarray]]:
        """(field path, array) of every coordinate (and, with ``radii``, every radius) the structure holds,
        e.g. ``("lobes[2].hull_vertices", (V, 3) array)``: the root, source points, branch points and radii,
        lobe points, hull vertices and centres (metres). Without ``radii``: exactly the arrays that
        ``map_positions`` maps."""
        for name in _HBL_POSITIONS:
            yield name, getattr(self, name)
        branch_fields = (*_BRANCH_POSITIONS, "radii") if radii else _BRANCH_POSITIONS
        for i, b in enumerate(self.branches):
            for name in branch_fields:
                yield f"branches[{i}].{name}", getattr(b, name)
        for j, lb in enumerate(self.lobes):
            for name in _LOBE_POSITIONS:
                yield f"lobes[{j}].{name}", getattr(lb, name)

    def map_positions(self, fn: Callable[[np.ndarray], Any]) -> HBL:
        """A new (validated) HBL with every position array ``a`` of ``arrays(radii=False)`` replaced by
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
    """Hex SHA-256 of the source file's bytes ('' when not from a file)."""
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


MIN_SCALE, MAX_SCALE = 1e-6, 1e6
"""Range of the uniform scale of a placement or a lobe edit: far beyond any real use (sessions saved
before the bound held scales like 0.0005, and a tighter range made them unreadable), narrow enough
that every product of the transforms stays finite in float64 (a scale of 1e308 made NaNs)."""
MAX_OFFSET = 1e7
"""Largest translation, metres, of a placement or a lobe edit along any axis (10,000 km: a tree placed
at its UTM northing, up to 9,300 km, or at geocentric coordinates, up to 6,400 km, still fits)."""


MAX_SKETCH_COORDINATE = 1e8
"""Largest magnitude, metres, of any coordinate or radius of a sketched example (``Assembly.sketches``).
A sketch is drawn in the world, its stroke samples within ``MAX_OFFSET`` of the origin and at most 10 km
of strokes in all (``service.handlers.assembly``), and kept in a frame at its root: its coordinates are
differences of two such samples (up to 2e7 m) plus lobe hulls reaching at most twice their stroke's
spread beyond them (up to 2e4 m), so 1e8 m never refuses a sketch, while a placed one (scale up to 1e6,
translation up to 1e7 m) stays far inside float32 and float64. Library examples are not bounded by it:
decomposed without a target height they keep the scan's frame and units, up to 1e12
(``decompose.preprocess.MAX_COORDINATE``)."""


def _check_scale(where: str, s: float) -> None:
    if not (math.isfinite(s) and MIN_SCALE <= s <= MAX_SCALE):
        raise ValidationError(f"{where}: must be a number in [{MIN_SCALE:g}, {MAX_SCALE:g}], got {s:.6g}")


def _check_offset(where: str, T: np.ndarray) -> None:
    if np.abs(T[:3, 3]).max() > MAX_OFFSET:
        raise ValidationError(f"{where}: translation {np.abs(T[:3, 3]).max():.3g} m exceeds {MAX_OFFSET:g} m")


def _check_similarity(owner: object, name: str, T: np.ndarray) -> None:
    """``T``: a rotation with a uniform scale in range, a translation in range, last row (0, 0, 0, 1)."""
    where = f"{type(owner).__name__}.{name}"
    R = T[:3, :3]
    s = float(np.cbrt(np.linalg.det(R))) if np.abs(R).max() <= 2 * MAX_SCALE else math.inf
    if s > 0 and math.isfinite(s):
        ok = np.allclose(R @ R.T, s * s * np.eye(3), atol=1e-6 * max(1.0, s * s))
        if not ok or not np.allclose(T[3], [0, 0, 0, 1]):
            raise ValidationError(f"{where}: must be a rotation, a positive uniform scale and a translation")
    _check_scale(f"{where} scale", s)
    _check_offset(where, T)


@dataclass(frozen=True, eq=False)
class LobeTransform:
    """A per-lobe edit inside a placed example: a 4x4 similarity applied in the example frame."""

    lobe: int
    """Index into the example's ``structure.lobes``."""
    T_example_lobe: F64
    """(4, 4) float64: rotation, uniform scale and translation applied about the lobe centre."""

    def __post_init__(self) -> None:
        T = frozen_array(self, "T_example_lobe", self.T_example_lobe, np.float64, (4, 4))
        if self.lobe < 0:
            raise ValidationError(f"LobeTransform.lobe: {self.lobe} is not a lobe index (0 or more)")
        _check_similarity(self, "T_example_lobe", T)


def _check_rigid(owner: object, name: str, T: np.ndarray) -> None:
    R = T[:3, :3]
    if np.abs(R).max() > 1.5 or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or not math.isclose(
        float(np.linalg.det(R)), 1.0, abs_tol=1e-6
    ) or not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValidationError(f"{type(owner).__name__}.{name}: must be a rigid transform (rotation + translation)")


@dataclass(frozen=True, eq=False)
class Placement:
    """An example placed in an assembly."""

    instance: str
    """Assembly-unique name of this placement."""
    example_id: str
    """The library example's id, or a sketched example's id from ``Assembly.sketches``."""
    T_world_example: F64
    """(4, 4) float64: rigid transform from the example frame to the world."""
    scale: float = 1.0
    """Uniform scale applied in the example frame before ``T_world_example``."""
    lobe_transforms: tuple[LobeTransform, ...] = ()

    def __post_init__(self) -> None:
        T = frozen_array(self, "T_world_example", self.T_world_example, np.float64, (4, 4))
        _check_offset("Placement.T_world_example", T)
        _check_rigid(self, "T_world_example", T)
        _check_scale("Placement.scale", self.scale)
        object.__setattr__(self, "lobe_transforms", tuple(self.lobe_transforms))


@dataclass(frozen=True)
class MergeLink:
    """Two placements joined by recombination (Algorithm 1 applied across examples)."""

    a: str
    """Instance whose main branch is kept."""
    b: str
    """Instance whose main branch is merged into ``a``'s."""
    vertex_a: int
    """Vertex on ``a``'s main branch where ``b`` connects."""
    vertex_b: int
    """First vertex of ``b``'s main branch that was not merged."""


@dataclass(frozen=True, eq=False)
class Assembly:
    """A new tree under construction: placed examples, sketched examples and merge links.

    Built only valid, wherever it comes from (an edit, a file, a request): instance names unique, each
    link joining two placed instances, the links a forest (no instance merged into two placements, no
    cycle; checked in O(len(merges))) and every sketch within ``MAX_SKETCH_COORDINATE``.
    """

    placements: tuple[Placement, ...] = ()
    sketches: tuple[Example, ...] = ()
    """Examples created in the session from strokes (not stored in a library)."""
    merges: tuple[MergeLink, ...] = ()

    def __post_init__(self) -> None:
        for name in ("placements", "sketches", "merges"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        names = {p.instance for p in self.placements}
        if len(names) != len(self.placements):
            raise ValidationError("Assembly.placements: instance names must be unique")
        for m in self.merges:
            if m.a not in names or m.b not in names or m.a == m.b:
                raise ValidationError(f"Assembly.merges: link {m.a!r}-{m.b!r} must join two placed instances")
        _check_forest(self.merges)
        for i, sk in enumerate(self.sketches):
            if sk.structure.extent > MAX_SKETCH_COORDINATE:
                _refuse_far_sketch(i, sk.structure)


def _check_forest(merges: tuple[MergeLink, ...]) -> None:
    """``ValidationError`` unless every instance is merged into at most one other and following the
    links from any instance (``b`` to ``a``) ends at an unmerged one. O(len(merges)): each instance
    is walked once, then marked done."""
    parent: dict[str, str] = {}
    for m in merges:
        if m.b in parent:
            raise ValidationError(
                f"Assembly.merges: {m.b!r} is merged into two placements ({parent[m.b]!r} and {m.a!r})")
        parent[m.b] = m.a
    done: set[str] = set()
    for start in parent:
        path: dict[str, None] = {}
        name = start
        while name in parent and name not in done:
            path[name] = None
            name = parent[name]
            if name in path:
                loop = [*list(path)[list(path).index(name):], name]
                shown = " -> ".join(repr(n) for n in loop[:6]) + (" -> ..." if len(loop) > 6 else "")
                raise ValidationError(
                    f"Assembly.merges: the links through {name!r} form a cycle ({shown}: each merged into the next)")
        done.update(path)


def _refuse_far_sketch(i: int, s: HBL) -> None:
    """Raise the ``ValidationError`` naming the first array of sketch ``i`` beyond the bound."""
    for name, a in s.arrays():
        big = float(np.abs(a).max()) if a.size else 0.0
        if big > MAX_SKETCH_COORDINATE:
            raise ValidationError(f"Assembly.sketches[{i}].structure.{name}: a value of {big:.3g} m exceeds "
                                  f"{MAX_SKETCH_COORDINATE:g} m, farther than any sketch reaches")
