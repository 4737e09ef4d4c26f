"""Checked values of an assembly script's keys: names, numbers, whole numbers, vectors, strokes and
growth options. Each raises one ``InputError`` naming ``what`` (the operation and key, e.g.
``operation 2 (export): seed``), the form expected and the value given; nothing is truncated or
converted silently (``lobe: 1.7`` once ran as lobe 1, ``seed: abc`` was a traceback)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from arboretum_library.errors import InputError

MAX_INT = (1 << 63) - 1
"""Largest whole number a request carries (a signed 64-bit integer)."""


def name(v: Any, where: str, key: str) -> str:
    """An example id or instance name given as text (or a whole number, YAML's reading of ``as: 7``)."""
    if isinstance(v, bool) or not isinstance(v, str | int):
        raise InputError(f"{where}: {key} must be a name, got {show(v)}")
    return str(v)


def number(v: Any, what: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """``v`` as a finite float in [lo, hi]; ``InputError`` naming ``what`` otherwise."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise InputError(f"{what} must be a number, got {show(v)}")
    try:
        x = float(v)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x) or not lo <= x <= hi:
        span = f"a number from {lo:g} to {hi:g}" if math.isfinite(lo) else "a finite number"
        raise InputError(f"{what} must be {span}, got {show(v)}")
    return x


def whole(v: Any, what: str, lo: int, hi: int) -> int:
    """``v`` as an int in [lo, hi]: a whole number (2 or 2.0, never 1.7 nor true); ``InputError`` naming
    ``what`` and the range otherwise."""
    ok = not isinstance(v, bool) and (isinstance(v, int) or (isinstance(v, float) and v.is_integer()))
    if not ok or not lo <= v <= hi:
        span = f"from {lo} to {hi}" if hi < 1 << 62 or (ok and v > hi) else f">= {lo}"
        raise InputError(f"{what} must be a whole number {span}, got {show(v)}")
    return int(v)


def vector(v: Any, what: str, n: int, form: str, bound: float = math.inf) -> np.ndarray:
    """``v`` as (n,) float64, each entry a finite number within +-``bound``."""
    if not isinstance(v, list | tuple) or len(v) != n:
        raise InputError(f"{what} must be {form}, got {show(v)}")
    return np.array([number(x, what, -bound, bound) for x in v])


def strokes(v: Any, what: str) -> list[np.ndarray]:
    """Strokes as a list of (S_k, 3) float64 arrays; ``InputError`` naming the first bad stroke or point."""
    if not isinstance(v, list | tuple) or not v:
        raise InputError(f"{what} must be a list of strokes, each a list of [x, y, z] points, got {show(v)}")
    out = []
    for k, stroke in enumerate(v):
        where = f"{what}: stroke {k + 1}"
        if not isinstance(stroke, list | tuple) or not stroke:
            raise InputError(f"{where} must be a list of [x, y, z] points, got {show(stroke)}")
        for j, pt in enumerate(stroke):
            if not (isinstance(pt, list | tuple) and len(pt) == 3 and all(type(x) in (int, float) for x in pt)):
                vector(pt, f"{where}, point {j + 1}", 3, "[x, y, z] (3 numbers)")
        try:
            pts = np.array(stroke, dtype=np.float64)
            finite = bool(np.isfinite(pts).all())
        except OverflowError:  # a whole number beyond float64
            finite = False
        if not finite:  # every point has 3 numbers: the first non-finite one is named
            for j, pt in enumerate(stroke):
                vector(pt, f"{where}, point {j + 1}", 3, "[x, y, z] (3 numbers)")
        out.append(pts)
    return out


def options_of(v: Any, where: str) -> dict:
    """Growth options (``options:`` of the operation ``where``) checked by name, type and range
    (``GrowOptions``, and ``arboretum grow``'s limits on density and leaf_density); the map as given."""
    from arboretum_server.grow.options import GrowOptions

    what = f"{where}: options"
    if not isinstance(v, dict) or not all(isinstance(k, str) for k in v):
        raise InputError(f"{what} must be a map of growth options such as {{density: 0.5}}, got {show(v)}")
    types = {f.name: str(f.type) for f in dataclasses.fields(GrowOptions)}
    for key, value in v.items():
        if key not in types:
            raise InputError(f"{what}: unknown growth option {key!r}; they are {', '.join(types)}")
        _option(value, types[key], f"{what}: {key}")
    return _ranged(v, where)


def _option(v: Any, tp: str, what: str) -> None:
    if v is None and tp.endswith("| None"):
        return
    if tp.startswith("float"):
        number(v, what)
    elif tp == "int":
        whole(v, what, 0, MAX_INT)
    elif tp == "str":
        if not isinstance(v, str):
            raise InputError(f"{what} must be text, got {show(v)}")
    elif tp.startswith("Mapping"):  # lobe_density: lobe index -> multiplier
        if not isinstance(v, dict):
            raise InputError(f"{what} must be a map of lobe index to multiplier such as {{0: 0.5}}, got {show(v)}")
        for k, x in v.items():
            whole(int(k) if isinstance(k, str) and k.isdigit() else k, f"{what}: lobe index", 0, MAX_INT)
            number(x, f"{what}: {k}")


def _ranged(options: dict, where: str) -> dict:
    from arboretum_server.service.handlers.grow import checked_options

    try:
        checked_options(options)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    return options


def show(v: Any) -> str:
    """``v`` for an error message as a script spells it (text quoted, true, null), at most 60 characters."""
    if v is None or isinstance(v, bool):
        return {None: "null", True: "true", False: "false"}[v]
    text = repr(v) if isinstance(v, str) else str(v)
    return text if len(text) <= 60 else text[:57] + "..."
