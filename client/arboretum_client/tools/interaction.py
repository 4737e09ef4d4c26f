"""Hand events -> tool actions, for both modes (VRTree 3.3 and 3.5). Same code for desktop and VR.

Modeling: grip on a branch drags the whole example, grip on a lobe drags the lobe (committed on release);
a short trigger selects what the hand touches, or places the chosen library example when it touches
nothing; a long trigger draws a stroke; touchpad turns the strokes into a new example; menu deletes the
selected example, or with nothing selected chooses the next library example (the VR library browser).
Refinement: a short trigger selects lobes (several: merge); a long trigger over the cloud selects the
points near the stroke (insert) or, with one lobe selected, draws a split stroke; touchpad applies
insert / split / merge, whichever the selection calls for; menu removes the selected lobe.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_client.input.hands import HandEvent

from .actions import Actions
from .gizmo import drag_example, drag_lobe, place_at, scaled
from .state import REFINEMENT, ClientState


@dataclass
class Drag:
    """A grip drag in progress (for the preview and the commit on release)."""

    side: str
    name: str
    """Pick name dragged ('inst:NAME/branch:0' or 'inst:NAME/lobe:2')."""
    delta: np.ndarray
    scale: float = 1.0
    """Uniform scale asked for during the drag."""


def parse(name: str | None) -> tuple[str | None, str | None, int | None]:
    """'inst:A/lobe:2' -> ('A', 'lobe', 2); 'lobe:3' -> (None, 'lobe', 3); None -> (None, None, None)."""
    if not name:
        return None, None, None
    inst = None
    if name.startswith("inst:"):
        inst, _, name = name[5:].partition("/")
    kind, _, idx = name.partition(":")
    return inst, kind, int(idx) if idx.isdigit() else None


def ground_point(sample) -> np.ndarray:
    """Where the hand's ray meets the ground z = 0 (desktop), or the point below the hand (VR, or a ray
    that never meets the ground)."""
    pos, d = sample.position, np.asarray(sample.ray_dir, float)
    if sample.pixel is not None and d[2] < -1e-6:
        return pos + d * (-pos[2] / d[2])
    return pos * [1.0, 1.0, 0.0]


def dragged_lobe(p, lobe: int, drag: Drag) -> np.ndarray:
    """(4, 4) new T_example_lobe of ``p``'s lobe after ``drag`` (moved, turned, then scaled)."""
    old = next((lt.T_example_lobe for lt in p.lobe_transforms if lt.lobe == lobe), None)
    return scaled(drag_lobe(drag.delta, p.T_world_example, p.scale, old), drag.scale)


class Interaction:
    """Routes hand events to actions; keeps the drag and the strokes being drawn."""

    def __init__(self, state: ClientState, actions: Actions, brush: float = 0.05) -> None:
        self.state, self.actions = state, actions
        self.drags: dict[str, Drag] = {}
        self.brush = brush
        """Metres: points this close to a refinement stroke are selected."""

    def handle(self, ev: HandEvent, touched: str | None) -> None:
        kind = ev.kind
        if kind.startswith("grip"):
            self._grip(ev, touched)
        elif kind == "select":
            self._select(ev, touched)
        elif kind.startswith("sketch"):
            self._stroke(ev)
        elif kind == "touchpad":
            self.touchpad()
        elif kind == "menu":
            self.menu()

    # -- grip --------------------------------------------------------------------------------------
    def _grip(self, ev: HandEvent, touched: str | None) -> None:
        if ev.kind == "grip_start":
            inst, kind, _ = parse(touched)
            if inst is not None and self.state.mode != REFINEMENT:
                self.drags[ev.side] = Drag(ev.side, touched or "", np.eye(4))
            return
        drag = self.drags.get(ev.side)
        if drag is None or ev.delta is None:
            return
        drag.delta, drag.scale = ev.delta, ev.scale
        if ev.kind == "grip_end":
            del self.drags[ev.side]
            self.commit(drag)

    def commit(self, drag: Drag) -> None:
        inst, kind, idx = parse(drag.name)
        p = next((p for p in self.state.assembly.placements if p.instance == inst), None)
        if p is None or (np.allclose(drag.delta, np.eye(4), atol=1e-9) and drag.scale == 1.0):
            return
        if kind == "lobe" and idx is not None:
            self.actions.transform_lobe(p.instance, idx, dragged_lobe(p, idx, drag))
        else:
            self.actions.transform_example(p.instance, drag_example(drag.delta, p.T_world_example),
                                           p.scale * drag.scale)

    # -- trigger -----------------------------------------------------------------------------------
    def _select(self, ev: HandEvent, touched: str | None) -> None:
        s = self.state
        if touched is None or touched == "points":
            if s.mode != REFINEMENT and s.chosen is not None:
                self.actions.add_example(s.chosen, place_at(ground_point(ev.sample)))
            elif s.selection:
                s.selection = []
                s.touch_scene()
            return
        inst, kind, idx = parse(touched)
        name = touched if kind == "lobe" or s.mode == REFINEMENT else f"inst:{inst}"
        if s.mode == REFINEMENT:
            s.selection = [n for n in s.selection if n != name] if name in s.selection else [*s.selection, name]
        else:
            s.selection = [name]
        s.say(f"selected {', '.join(s.selection) or 'nothing'}")
        s.touch_scene()

    def _stroke(self, ev: HandEvent) -> None:
        live = self.state.live_stroke
        at = self._on_cloud(ev.sample)
        if ev.kind == "sketch_start":
            live[ev.side] = [at]
        elif ev.kind == "sketch_move" and ev.side in live:
            if np.linalg.norm(live[ev.side][-1] - at) > 1e-4:
                live[ev.side].append(at)
        elif ev.kind == "sketch_end" and ev.side in live:
            stroke = np.array(live.pop(ev.side) + [at])
            self._finish_stroke(stroke)

    def _on_cloud(self, sample) -> np.ndarray:
        """Where a stroke sample lands: a VR hand where it is; the desktop cursor (a ray) on the scan in
        refinement, at the cloud point nearest the eye among those within ``brush`` of the ray, so a
        stroke drawn over the points is on them (on the plane through the camera target it missed lobes
        off that plane by 0.13-0.16 m: insert selected nothing, split was refused); elsewhere, or with
        no point under the cursor, on that plane."""
        at = sample.position.copy()
        cloud = self.state.cloud
        if sample.pixel is None or self.state.mode != REFINEMENT or cloud is None or not len(cloud.points):
            return at
        d = np.asarray(sample.ray_dir, np.float64)
        rel = np.asarray(cloud.points, np.float64) - at
        t = rel @ d
        off = np.linalg.norm(rel - t[:, None] * d, axis=1)
        near = np.flatnonzero(off <= self.brush)
        if not len(near):
            return at
        return np.asarray(cloud.points[near[np.argmin(t[near])]], np.float64).copy()

    def _finish_stroke(self, stroke: np.ndarray) -> None:
        s = self.state
        lobes = [n for n in s.selection if n.startswith("lobe:")]
        if s.mode == REFINEMENT and not lobes and s.cloud is not None:
            d = np.linalg.norm(s.cloud.points[:, None, :].astype(np.float64) - stroke[None], axis=2).min(axis=1)
            picked = np.nonzero(d <= self.brush)[0]
            s.point_selection = np.union1d(s.point_selection, picked).astype(np.int64)
            s.say(f"{len(s.point_selection)} points selected: touchpad inserts a lobe")
        else:
            s.strokes.append(stroke)
            s.say(f"{len(s.strokes)} strokes: touchpad " + ("splits the lobe" if s.mode == REFINEMENT else "makes an example"))
        s.touch_scene()

    # -- boolean operations ------------------------------------------------------------------------
    def touchpad(self) -> None:
        s = self.state
        if s.mode != REFINEMENT:
            self.actions.sketch()
            return
        lobes = [int(n[5:]) for n in s.selection if n.startswith("lobe:")]
        if len(lobes) >= 2:  # lobes selected decide: points selected before are for an insert without them
            self.actions.merge_lobes(lobes)
        elif len(lobes) == 1 and s.strokes:
            strokes, s.strokes = s.strokes, []
            self.actions.split_lobe(lobes[0], strokes)
        elif not lobes and len(s.point_selection):
            self.actions.insert_lobe(s.point_selection)
        else:
            s.say("touchpad: select points (insert), one lobe and strokes (split) or lobes (merge)")

    def menu(self) -> None:
        s = self.state
        if s.mode == REFINEMENT:
            lobes = [int(n[5:]) for n in s.selection if n.startswith("lobe:")]
            if lobes:
                self.actions.remove_lobe(lobes[0])
            else:
                s.say("menu: select a lobe to remove it")
            return
        insts = {parse(n)[0] for n in s.selection} - {None}
        if not insts and s.library:  # nothing selected: browse the library (VR has no panel)
            ids = [r["id"] for r in s.library]
            nxt = ids[(ids.index(s.chosen) + 1) % len(ids)] if s.chosen in ids else ids[0]
            self.actions.choose(nxt)
        for inst in sorted(i for i in insts if i):
            self.actions.delete_example(inst)
