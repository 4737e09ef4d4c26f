"""The assembly records: examples placed (``Placement``, with per-lobe edits ``LobeTransform``), joined by
recombination (``MergeLink``) and sketched, in an ``Assembly`` (VRTree section 3.5), with the bounds
that keep every product of their transforms finite.

Like ``model``'s records they are frozen and validated on construction (``ValidationError`` naming the
field); an ``Assembly`` is valid wherever it comes from: an edit, a file or a request.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import ValidationError
from .model import F64, HBL, Example, frozen_array

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
(``pointio.MAX_COORDINATE``)."""


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
