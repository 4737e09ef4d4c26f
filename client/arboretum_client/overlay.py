"""The overlay scene: touch balls, pointing rays, strokes and drag previews (small, rebuilt on change).

Touch balls are blue (left hand) and red (right hand), as in VRTree section 3.3. A dragged example or
lobe is previewed as thin lines at its new place until the server confirms the edit.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from arboretum_library.assembly import LobeTransform
from arboretum_library.errors import ValidationError

from .assembly_view import placed_hbl
from .input.hands import HAND_COLORS, HandSample
from .scene import Polyline, Scene
from .tools.gizmo import drag_example
from .tools.interaction import Drag, dragged_lobe, parse
from .tools.state import ClientState
from .tools.view import hand_ball

STROKE_COLOR = (0.1, 0.6, 0.95)
PREVIEW_COLOR = (1.0, 0.55, 0.0)


def overlay_key(state: ClientState, samples: list[HandSample], drags: dict[str, Drag]) -> tuple:
    """Changes when the overlay must be rebuilt (poses rounded to 0.1 mm)."""
    hands = tuple((s.side, tuple(np.round(s.T_world_hand[:3, 3], 4)), s.tracked) for s in samples)
    strokes = (len(state.strokes), tuple((k, len(v)) for k, v in state.live_stroke.items()))
    moving = tuple((d.side, d.name, tuple(np.round(d.delta.ravel(), 4)), d.scale) for d in drags.values())
    return hands, strokes, moving, state.scene_version


def _line(points: np.ndarray, color, width: float = 3.0) -> Polyline | None:
    pts = np.asarray(points, np.float32).reshape(-1, 3)
    if len(pts) < 2:
        return None
    return Polyline(points=pts, radii=np.zeros(len(pts), np.float32), color=color, style="line", width_px=width)


def _preview(state: ClientState, drag: Drag) -> list:
    """Lines of the dragged placement or lobe where the drag would put it; none where that is out of
    the model's range (a scale beyond 1e6, say: the server refuses such an edit too)."""
    try:
        return _preview_lines(state, drag)
    except ValidationError:
        return []


def _preview_lines(state: ClientState, drag: Drag) -> list:
    inst, kind, idx = parse(drag.name)
    p = next((p for p in state.assembly.placements if p.instance == inst), None)
    ex = state.examples.get(p.example_id) if p is not None else None
    if p is None or ex is None:
        return []
    if kind == "lobe" and idx is not None:
        lt = LobeTransform(idx, dragged_lobe(p, idx, drag))
        moved = dataclasses.replace(p, lobe_transforms=(*[t for t in p.lobe_transforms if t.lobe != idx], lt))
        hbl = placed_hbl(ex.structure, moved)
        hull = hbl.lobes[idx].hull_vertices
        return [ln for ln in (_line(hull[f], PREVIEW_COLOR, 2.0) for f in ex.structure.lobes[idx].hull_faces) if ln]
    moved = dataclasses.replace(p, T_world_example=drag_example(drag.delta, p.T_world_example),
                                scale=p.scale * drag.scale)
    hbl = placed_hbl(ex.structure, moved)
    return [ln for ln in (_line(b.points, PREVIEW_COLOR, 3.0) for b in hbl.branches) if ln]


def overlay_scene(state: ClientState, samples: list[HandSample], drags: dict[str, Drag], view_distance: float) -> Scene:
    items: list = []
    radius = max(0.012 * view_distance, 0.01)
    for s in samples:
        if s.tracked and (s.pixel is None or s.buttons or drags.get(s.side)):
            items.append(hand_ball(s.position, radius, HAND_COLORS[s.side]))
    for stroke in state.strokes:
        items.append(_line(stroke, STROKE_COLOR, 3.0))
    for pts in state.live_stroke.values():
        items.append(_line(np.array(pts), STROKE_COLOR, 3.0))
    for d in drags.values():
        items += _preview(state, d)
    return Scene(items=tuple(it for it in items if it is not None))
