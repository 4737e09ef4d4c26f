"""An assembly script checked whole before anything runs: every operation's keys, values and paths.

``check_ops`` turns the one-key maps read from a script into ``Op`` records, or raises one
``InputError`` naming the operation (``operation 3 (transform): ...``) and the key. What can be known
without running is checked here: unknown or missing keys, types (whole numbers are whole, numbers
finite, scales and offsets in the model's range, rotation axes non-zero, strokes of [x, y, z] points,
growth options by name and type) and every export's ``out`` (``outputs.check_output``: not inside the
library, not one of the script's inputs, its folder writable). What depends on the assembly (an
instance that does not exist, a lobe index beyond the example's lobes, a tree too large to grow) is
found when the operation runs (``script.Runner``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from arboretum_library.assembly import MAX_OFFSET, MAX_SCALE, MIN_SCALE, LobeTransform, Placement
from arboretum_library.errors import InputError, ValidationError
from arboretum_library.geometry import axis_angle_matrix

from .script_values import MAX_INT, name, number, options_of, show, strokes, vector, whole

POSE = ("at", "rotate", "rotate_z", "scale", "T")
KEYS: dict[str, tuple[str, ...]] = {
    "add": ("example", "as", *POSE), "transform": ("instance", *POSE),
    "transform_lobe": ("instance", "lobe", *POSE), "sketch": ("strokes", "as"), "delete": ("instance",),
    "undo": (), "redo": (), "export": ("out", "seed", "lod", "options"),
}
"""The keys each operation takes (``REQUIRED``: those it must have); any other key is refused."""
REQUIRED = {"add": ("example",), "transform": ("instance",), "transform_lobe": ("instance", "lobe"),
            "sketch": ("strokes",), "delete": ("instance",), "export": ("out",)}
EXPORT_SUFFIXES = (".glb", ".obj", ".ply")


@dataclass(frozen=True)
class Pose:
    """The transform keys one operation gave; None where a key was left out."""

    T: np.ndarray | None = None
    """(4, 4) float64: rigid for add / transform, a similarity (with its scale) for transform_lobe."""
    R: np.ndarray | None = None
    """(3, 3) float64 rotation from ``rotate`` or ``rotate_z``."""
    at: np.ndarray | None = None
    """(3,) float64 translation, metres."""
    scale: float | None = None
    """Uniform scale."""


@dataclass(frozen=True)
class Op:
    """One checked operation: ``index`` from 0, its ``kind`` and its checked ``args``."""

    index: int
    kind: str
    args: dict[str, Any] = field(default_factory=dict)

    @property
    def where(self) -> str:
        return f"operation {self.index + 1} ({self.kind})"


def check_ops(ops: list[dict], *, inputs=(), outputs=(), libraries=()) -> list[Op]:
    """Checked ``ops`` (each a one-key map); ``InputError`` at the first mistake. ``inputs``, ``outputs``
    and ``libraries``: paths no export may write (the script, ``--from``; ``--out``; ``--library``)."""
    checked, outs = [], list(outputs)
    for i, op in enumerate(ops):
        (kind, spec), = op.items()
        where = f"operation {i + 1} ({kind})"
        args = _checked_keys(kind, spec, where)
        if kind == "export":
            args = _export(args, where, inputs, outs, libraries)
            outs.append(args["out"])
        elif kind == "sketch":
            args = {"strokes": strokes(args["strokes"], f"{where}: strokes"), "as": name(args.get("as", ""), where, "as")}
        elif kind == "delete":
            args = {"instance": name(args["instance"], where, "instance")}
        elif kind in ("add", "transform", "transform_lobe"):
            args = _placement_args(kind, args, where)
        checked.append(Op(i, kind, args))
    return checked


def _checked_keys(kind: str, spec: Any, where: str) -> dict:
    if kind not in KEYS:
        raise InputError(f"{where}: unknown operation (use {', '.join(KEYS)})")
    spec = {} if spec is None else spec
    if not isinstance(spec, dict):
        raise InputError(f"{where}: its arguments must be a map such as {{{', '.join(f'{k}: ...' for k in REQUIRED.get(kind, ()))}}}")
    for key in spec:
        if key not in KEYS[kind]:
            takes = f"takes {', '.join(KEYS[kind])}" if KEYS[kind] else "takes no arguments"
            hint = " (growth options go inside options: {...})" if kind == "export" and _is_growth_option(key) else ""
            raise InputError(f"{where}: unknown key {key!r}; {kind} {takes}{hint}")
    for key in REQUIRED.get(kind, ()):
        if key not in spec:
            raise InputError(f"{where}: missing argument {key!r}")
    return spec


def _is_growth_option(key: Any) -> bool:
    import dataclasses

    from arboretum_server.grow.options import GrowOptions

    return key in {f.name for f in dataclasses.fields(GrowOptions)}


def _placement_args(kind: str, spec: dict, where: str) -> dict:
    args: dict[str, Any] = {"pose": pose(spec, where, lobe=kind == "transform_lobe")}
    if kind == "add":
        args.update(example=name(spec["example"], where, "example"), instance=name(spec.get("as", ""), where, "as"))
    else:
        args["instance"] = name(spec["instance"], where, "instance")
        if not any(k in spec for k in POSE):
            raise InputError(f"{where}: nothing to change; give at, rotate, rotate_z, scale or T")
    if kind == "transform_lobe":
        args["lobe"] = whole(spec["lobe"], f"{where}: lobe", 0, MAX_INT)
    return args


def _export(spec: dict, where: str, inputs, outputs, libraries) -> dict:
    from arboretum_library.outputs import check_output

    out = spec["out"]
    if not isinstance(out, str) or not out:
        raise InputError(f"{where}: out must be a file name such as tree.glb, got {show(out)}")
    p = Path(out)
    if p.suffix.lower() not in EXPORT_SUFFIXES:
        raise InputError(f"{where}: out {p}: writes .glb, .ply or .obj (zipped with its MTL and textures "
                         f"as .zip) files, not {p.suffix or 'a file without suffix'}")
    written = p.with_suffix(".zip") if p.suffix.lower() == ".obj" else p
    check_output(written, f"{where}: out", inputs=inputs, outputs=outputs, libraries=libraries)
    from arboretum_server.mesh.lod import MAX_LEVEL

    seed = spec.get("seed", 0)
    if isinstance(seed, int | float) and not isinstance(seed, bool) and seed < 0:
        raise InputError(f"{where}: seed must not be negative, got {show(seed)}")
    return {"out": written, "format": p.suffix.lower().lstrip("."),
            "seed": whole(seed, f"{where}: seed", 0, MAX_INT),
            "lod": whole(spec.get("lod", 0), f"{where}: lod", 0, MAX_LEVEL),
            "options": options_of(spec.get("options", {}), where)}


def pose(spec: dict, where: str, lobe: bool = False) -> Pose:
    """The ``Pose`` of ``spec``'s transform keys (``lobe``: ``T`` is a similarity holding the scale)."""
    if "T" in spec and (also := [k for k in ("at", "rotate", "rotate_z") + (("scale",) if lobe else ()) if k in spec]):
        holds = "rotation, scale and translation" if lobe else "rotation and translation"
        raise InputError(f"{where}: give T or {', '.join(also)}, not both (T holds the {holds})")
    if "rotate" in spec and "rotate_z" in spec:
        raise InputError(f"{where}: give rotate or rotate_z, not both")
    out = Pose()
    if "scale" in spec:
        out = Pose(scale=number(spec["scale"], f"{where}: scale", MIN_SCALE, MAX_SCALE))
    if "T" in spec:
        return Pose(T=_matrix(spec["T"], where, lobe), scale=out.scale)
    R = None
    if "rotate" in spec:
        R = _rotation(vector(spec["rotate"], f"{where}: rotate", 4, "[axis x, axis y, axis z, degrees]"), where)
    elif "rotate_z" in spec:
        R = axis_angle_matrix(np.array([0.0, 0, 1]), math.radians(number(spec["rotate_z"], f"{where}: rotate_z")))
    at = None
    if "at" in spec:
        at = vector(spec["at"], f"{where}: at", 3, "[x, y, z] (metres)", MAX_OFFSET)
    return Pose(R=R, at=at, scale=out.scale)


def _rotation(v: np.ndarray, where: str) -> np.ndarray:
    axis, deg = v[:3], v[3]
    big = np.abs(axis).max()
    if big == 0:
        raise InputError(f"{where}: rotate: the axis [0, 0, 0] is zero; give [axis x, axis y, axis z, degrees] "
                         "with a non-zero axis, e.g. [0, 0, 1, 45]")
    return axis_angle_matrix(axis / big, math.radians(deg))


def _matrix(v: Any, where: str, lobe: bool) -> np.ndarray:
    rows = v if isinstance(v, list | tuple) and len(v) == 4 else None
    if rows is None or not all(isinstance(r, list | tuple) and len(r) == 4 for r in rows):
        raise InputError(f"{where}: T must be a 4x4 matrix (4 rows of 4 numbers), got {show(v)}")
    T = np.array([[number(x, f"{where}: T") for x in r] for r in rows])
    try:
        LobeTransform(0, T) if lobe else Placement("check", "check", T)
    except ValidationError as exc:
        why = str(exc).replace("LobeTransform.T_example_lobe", "T").replace("Placement.T_world_example", "T")
        raise InputError(f"{where}: {why}") from None
    return T
