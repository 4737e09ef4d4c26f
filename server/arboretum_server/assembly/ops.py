"""The assembly edits of VRTree 3.5 as pure functions: (Assembly, inputs) -> (Assembly, Outcome).

select (add) example, transform example, transform lobe, delete example and sketch a new example;
placing or moving an example runs recombination for it. The service's session handlers (also run
in-process by ``arboretum assemble``) commit each outcome to a ``state.History``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from arboretum_library.assembly import Assembly, LobeTransform, Placement
from arboretum_library.errors import InputError, ValidationError

from .recombine import RecombineOptions, recombine
from .sketch import SketchOptions, sketch_example
from .world import ExampleSource, resolver


@dataclass(frozen=True)
class Outcome:
    """What an edit did."""

    label: str
    instance: str = ""
    merged: tuple[str, ...] = ()
    kinds: tuple[str, ...] = ()


def _placement(assembly: Assembly, instance: str) -> tuple[int, Placement]:
    for i, p in enumerate(assembly.placements):
        if p.instance == instance:
            return i, p
    raise InputError(f"no placement {instance!r} in this session")


def _new_instance(assembly: Assembly, stem: str) -> str:
    taken = {p.instance for p in assembly.placements}
    n = 1
    while f"{stem}#{n}" in taken:
        n += 1
    return f"{stem}#{n}"


def _check_name(instance: str) -> str:
    if not re.fullmatch(r"[\w#.:-]{1,128}", instance):
        raise InputError(f"instance name {instance!r}: use 1-128 letters, digits or - _ # . :")
    return instance


def _placed(instance: str, example_id: str, T: np.ndarray, scale: float, lts: tuple = ()) -> Placement:
    try:
        return Placement(instance, example_id, T, float(scale), lts)
    except ValidationError as exc:
        raise InputError(str(exc)) from None


def add_example(assembly: Assembly, get: ExampleSource, example_id: str, T_world_example: np.ndarray,
                scale: float = 1.0, instance: str = "",
                o: RecombineOptions = RecombineOptions()) -> tuple[Assembly, Outcome]:
    """Place example ``example_id`` (library or sketch) and recombine it with the others."""
    source = resolver(assembly, get)
    source(example_id)  # raises if it does not exist
    name = _check_name(instance) if instance else _new_instance(assembly, example_id)
    if any(p.instance == name for p in assembly.placements):
        raise InputError(f"placement {name!r} already exists in this session")
    p = _placed(name, example_id, T_world_example, scale)
    out, merged = recombine(replace(assembly, placements=assembly.placements + (p,)), source, name, o)
    return out, Outcome(f"add {example_id} as {name}", name, merged)


def transform_example(assembly: Assembly, get: ExampleSource, instance: str, T_world_example: np.ndarray,
                      scale: float = 1.0, o: RecombineOptions = RecombineOptions()) -> tuple[Assembly, Outcome]:
    """Move, turn and scale placement ``instance``, then recombine it."""
    i, p = _placement(assembly, instance)
    q = _placed(instance, p.example_id, T_world_example, scale, p.lobe_transforms)
    placements = assembly.placements[:i] + (q,) + assembly.placements[i + 1:]
    out, merged = recombine(replace(assembly, placements=placements), resolver(assembly, get), instance, o)
    return out, Outcome(f"transform {instance}", instance, merged)


def transform_lobe(assembly: Assembly, get: ExampleSource, instance: str, lobe: int,
                   T_example_lobe: np.ndarray) -> tuple[Assembly, Outcome]:
    """Set the similarity (about its centre) of lobe ``lobe`` of placement ``instance``."""
    i, p = _placement(assembly, instance)
    n = len(resolver(assembly, get)(p.example_id).structure.lobes)
    if not 0 <= lobe < n:
        raise InputError(f"lobe {lobe} does not exist: {p.example_id!r} has {n} lobes")
    T = np.asarray(T_example_lobe, dtype=np.float64)
    R = T[:3, :3]
    s = np.cbrt(np.linalg.det(R)) if T.shape == (4, 4) else 0.0
    if s <= 0 or not np.allclose(R @ R.T, s * s * np.eye(3), atol=1e-6 * max(1.0, s * s)):
        raise InputError("transform lobe: T_example_lobe must be a rotation, a positive uniform scale and a translation")
    lts = tuple(lt for lt in p.lobe_transforms if lt.lobe != lobe) + (LobeTransform(lobe, T),)
    q = replace(p, lobe_transforms=tuple(sorted(lts, key=lambda lt: lt.lobe)))
    placements = assembly.placements[:i] + (q,) + assembly.placements[i + 1:]
    return replace(assembly, placements=placements), Outcome(f"transform lobe {lobe} of {instance}", instance)


def delete_example(assembly: Assembly, instance: str) -> tuple[Assembly, Outcome]:
    """Remove placement ``instance``, its merge links, and its sketch if nothing else uses it."""
    i, p = _placement(assembly, instance)
    placements = assembly.placements[:i] + assembly.placements[i + 1:]
    merges = tuple(m for m in assembly.merges if instance not in (m.a, m.b))
    used = {q.example_id for q in placements}
    sketches = tuple(s for s in assembly.sketches if s.id in used or s.id != p.example_id)
    out = Assembly(placements, sketches, merges)
    return out, Outcome(f"delete {instance}", instance)


def sketch(assembly: Assembly, get: ExampleSource, strokes: Sequence[np.ndarray], instance: str = "",
           o: RecombineOptions = RecombineOptions(), so: SketchOptions = SketchOptions()) -> tuple[Assembly, Outcome]:
    """A new example from ``strokes`` (world frame), placed where it was drawn and recombined."""
    if not len(strokes):
        raise InputError("sketch: no strokes")
    taken = {s.id for s in assembly.sketches}
    n = 1
    while f"sketch-{n:04d}" in taken:
        n += 1
    ex, T, kinds = sketch_example(strokes, f"sketch-{n:04d}", so)
    with_sketch = replace(assembly, sketches=assembly.sketches + (ex,))
    out, res = add_example(with_sketch, get, ex.id, T, 1.0, instance, o)
    return out, replace(res, label=f"sketch {ex.id} ({', '.join(kinds)}) as {res.instance}", kinds=kinds)
