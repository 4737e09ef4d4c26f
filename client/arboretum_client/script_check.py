"""Checks of a client script's steps before anything runs: one ``InputError`` naming the step number, its
key and the problem (never a traceback from deep inside the runner, never a silently ignored step).

What can only be known while running (an example id the library does not have, a pick name not in the
scene) is checked by ``ScriptRunner`` after the step, with the same kind of message.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from arboretum_library.errors import InputError

from .camera import VIEWS
from .input.hands import BUTTONS as HAND_BUTTONS
from .input.hands import SIDES
from .ui_actions import SIMPLE, WITH_ARG

MOUSE_BUTTONS = ("left", "right", "middle")
MODIFIERS = ("ctrl", "shift", "alt")
NAMED_KEYS = frozenset({"tab", "enter", "escape", "backspace", "delete", "space", *MODIFIERS,
                        *(f"f{i}" for i in range(1, 13))})
"""Key names besides single printable characters (lower case, as the window reports them)."""
MAX_WAIT = 3600.0
"""Seconds: a longer ``wait`` is surely a typo (it would run 108,000 virtual frames)."""


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _point(v, n: int = 3) -> bool:
    return isinstance(v, list | tuple) and len(v) == n and all(_number(c) for c in v)


def _xy(v) -> str | None:
    return None if _point(v, 2) else f"expected a pixel [x, y], got {v!r}"


def _xyz(v) -> str | None:
    return None if _point(v) else f"expected a world point [x, y, z] in metres, got {v!r}"


def _button(v) -> str | None:
    return None if v in MOUSE_BUTTONS else f"unknown mouse button {v!r} (one of {', '.join(MOUSE_BUTTONS)})"


def _key(v) -> str | None:
    if isinstance(v, str) and ((len(v) == 1 and v.isprintable() and not v.isspace() and v == v.lower())
                               or v in NAMED_KEYS):
        return None
    return (f"unknown key {v!r} (a lower-case character, tab, enter, escape, backspace, delete, space, f1..f12, "
            f"or a modifier {', '.join(MODIFIERS)})")


def _modifier(v) -> str | None:
    return None if v in MODIFIERS else f"unknown modifier {v!r} (one of {', '.join(MODIFIERS)})"


def _wait(v) -> str | None:
    return None if _number(v) and 0 <= v <= MAX_WAIT else f"expected seconds 0..{MAX_WAIT:g}, got {v!r}"


def check_action(v) -> str | None:
    """None if ``v`` is an action ``App.ui_action`` runs (``ui_actions``), else the problem."""
    if not isinstance(v, str):
        return f"expected an action name, got {v!r}"
    head, _, arg = v.partition(":")
    entry = WITH_ARG.get(head)
    if v in SIMPLE:
        return None
    if entry is None:
        return f"unknown action {v!r} (one of {', '.join(sorted(SIMPLE))}, or choose:ID, tag:T, toggle:T, " \
               "density:+/-, search:, focus:+)"
    if entry.choices is not None:
        return None if arg in entry.choices else f"{head}: expects one of {', '.join(entry.choices)}, got {arg!r}"
    return f"{head}: needs {entry.needs}" if entry.needs and not arg.strip() else None


def _stroke(v) -> str | None:
    if isinstance(v, list) and v and all(_point(p) for p in v):
        return None
    return f"expected a list of world points [[x, y, z], ...], got {v!r}"


def _drag(v) -> str | None:
    if not isinstance(v, dict) or not {"from", "to"} <= set(v) or set(v) - {"from", "to", "button"}:
        return f"expected {{'from': [x, y, z], 'to': [x, y, z], 'button': 'right'}}, got {v!r}"
    problem = _xyz(v["from"]) or _xyz(v["to"])
    return problem or (_button(v["button"]) if "button" in v else None)


def _hands(v) -> str | None:
    if v is None:
        return None
    if not isinstance(v, list):
        return f"expected a list of hand samples or null, got {v!r}"
    for j, h in enumerate(v):
        where = f"hand {j + 1}"
        if not isinstance(h, dict) or not {"side", "position"} <= set(h) or set(h) - {"side", "position", "buttons"}:
            return f"{where}: expected {{'side': 'left', 'position': [x, y, z], 'buttons': [...]}}, got {h!r}"
        if h["side"] not in SIDES:
            return f"{where}: side must be one of {', '.join(SIDES)}, got {h['side']!r}"
        if not _point(h["position"]):
            return f"{where}: expected a position [x, y, z], got {h['position']!r}"
        buttons = h.get("buttons", [])
        bad = [b for b in buttons if b not in HAND_BUTTONS] if isinstance(buttons, list) else [buttons]
        if bad:
            return f"{where}: unknown button {bad[0]!r} (one of {', '.join(HAND_BUTTONS)})"
    return None


def _select(v) -> str | None:
    names = [v] if isinstance(v, str) else v
    if isinstance(names, list) and names and all(isinstance(n, str) and n for n in names):
        return None
    return f"expected a pick name or a list of them, e.g. ['lobe:2'] or 'inst:NAME', got {v!r}"


def _view(v) -> str | None:
    return None if v in VIEWS else f"unknown view {v!r} (one of {', '.join(VIEWS)})"


def _screenshot(v) -> str | None:
    return None if isinstance(v, str) and v.strip() else f"expected a PNG path, got {v!r}"


def _reference(v) -> str | None:
    if v is None or (isinstance(v, str) and v):
        return None
    if isinstance(v, dict) and isinstance(v.get("image"), str) and not set(v) - {"image", "height"}:
        h = v.get("height", 1.0)
        return None if _number(h) and h > 0 else f"height must be a positive number of metres, got {h!r}"
    return f"expected an image path, {{'image': path, 'height': metres}} or null, got {v!r}"


CHECKS: dict[str, Callable[[object], str | None]] = {
    "mouse": _xy, "world": _xyz, "press": _button, "release": _button, "click": _button, "key": _key,
    "hold": _modifier, "unhold": _modifier, "wait": _wait, "action": check_action, "stroke": _stroke,
    "drag": _drag, "hands": _hands, "select": _select, "view": _view, "screenshot": _screenshot,
    "reference": _reference,
}
"""Step name -> a function of its argument giving the problem (None when fine)."""


def check_steps(steps: list) -> None:
    """``InputError`` for the first malformed step: 'script step N (KEY): problem'."""
    for i, step in enumerate(steps):
        if not isinstance(step, dict) or len(step) != 1:
            raise InputError(f"script step {i + 1}: expected one key, got {step!r}")
        (name, arg), = step.items()
        check = CHECKS.get(name)
        if check is None:
            raise InputError(f"script step {i + 1}: unknown step {name!r} (one of {', '.join(CHECKS)})")
        problem = check(arg)
        if problem:
            raise InputError(f"script step {i + 1} ({name}): {problem}")
