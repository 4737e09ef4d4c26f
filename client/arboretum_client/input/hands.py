"""The two-hands model shared by the desktop and VR backends (VRTree section 3.3).

A backend reports, each frame, one ``HandSample`` per hand: a 6-DoF pose ``T_world_hand``, a pointing
ray, the four buttons (grip, trigger, touchpad, menu) and the touchpad position. ``HandTracker`` turns
the samples of one hand over time into ``HandEvent``s, the only thing tools see:

- grip: ``grip_start`` / ``grip_move`` (with ``delta`` = T_now @ inv(T_start)) / ``grip_end``;
- trigger: released before ``LONG_PRESS`` seconds = ``select``; held longer = ``sketch_start``,
  ``sketch_move`` (one per frame, with the hand position) and ``sketch_end`` on release;
- touchpad and menu: ``touchpad`` / ``menu`` on press (boolean operations: merge, split, ...).

The left hand is blue and the right hand red, as the paper's touch balls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LEFT, RIGHT = "left", "right"
SIDES = (LEFT, RIGHT)
HAND_COLORS: dict[str, tuple[float, float, float]] = {LEFT: (0.15, 0.35, 0.95), RIGHT: (0.95, 0.15, 0.12)}
"""Touch-ball and highlight colour of each hand (VRTree: blue and red)."""
BUTTONS = ("grip", "trigger", "touchpad", "menu")
LONG_PRESS = 0.35
"""Seconds: a trigger held longer than this starts a sketch instead of a selection."""


@dataclass(frozen=True, eq=False)
class HandSample:
    """One hand's state at one instant, from any backend."""

    side: str
    """'left' or 'right'."""
    T_world_hand: np.ndarray = field(default_factory=lambda: np.eye(4))
    """(4, 4) float64 pose of the hand (touch-ball centre and orientation), world frame."""
    ray_dir: tuple[float, float, float] = (0.0, 0.0, -1.0)
    """Unit pointing direction, world frame (VR: the controller's -Z; desktop: through the cursor)."""
    buttons: frozenset[str] = frozenset()
    """Names of the buttons held, from ``BUTTONS``."""
    touchpad: tuple[float, float] = (0.0, 0.0)
    """Touchpad (or thumbstick) position, -1..1 each."""
    pixel: tuple[float, float] | None = None
    """Desktop only: the cursor in output pixels (picks through the ID buffer)."""
    tracked: bool = True
    scale: float = 1.0
    """Scale gesture while the grip is held (desktop: the wheel; VR: the touchpad), 1 = none."""

    @property
    def position(self) -> np.ndarray:
        return self.T_world_hand[:3, 3]


@dataclass(frozen=True, eq=False)
class HandEvent:
    """What a tool reacts to."""

    side: str
    kind: str
    """grip_start, grip_move, grip_end, select, sketch_start, sketch_move, sketch_end, touchpad, menu."""
    sample: HandSample
    delta: np.ndarray | None = None
    """(4, 4) T_now @ inv(T_at_grip_start) for grip events; None otherwise."""
    scale: float = 1.0
    """Grip events: the uniform scale asked for since the grip started (``HandSample.scale``)."""


class HandTracker:
    """Turns one hand's samples over time into events (press lengths, grip deltas)."""

    def __init__(self, side: str) -> None:
        self.side = side
        self.held: frozenset[str] = frozenset()
        self.trigger_since: float | None = None
        self.press_sample: HandSample | None = None
        self.sketching = False
        self.grip_start: np.ndarray | None = None
        self.last: HandSample = HandSample(side)

    def update(self, s: HandSample, t: float) -> list[HandEvent]:
        """Events caused by sample ``s`` taken at time ``t`` (seconds, monotonic)."""
        pressed, released = s.buttons - self.held, self.held - s.buttons
        self.held, self.last = s.buttons, s
        out: list[HandEvent] = []
        out += self._grip(s, pressed, released)
        out += self._trigger(s, t, pressed, released)
        out += [HandEvent(self.side, b, s) for b in ("touchpad", "menu") if b in pressed]
        return out

    def _grip(self, s: HandSample, pressed, released) -> list[HandEvent]:
        if "grip" in pressed:
            self.grip_start = s.T_world_hand.copy()
            return [HandEvent(self.side, "grip_start", s, np.eye(4))]
        if self.grip_start is None:
            return []
        delta = s.T_world_hand @ np.linalg.inv(self.grip_start)
        if "grip" in released:
            self.grip_start = None
            return [HandEvent(self.side, "grip_end", s, delta, s.scale)]
        return [HandEvent(self.side, "grip_move", s, delta, s.scale)]

    def _trigger(self, s: HandSample, t: float, pressed, released) -> list[HandEvent]:
        if "trigger" in pressed:
            self.trigger_since, self.press_sample = t, s
            return []
        if self.trigger_since is None:
            return []
        if "trigger" in released:
            was_sketching, self.trigger_since, self.sketching = self.sketching, None, False
            return [HandEvent(self.side, "sketch_end" if was_sketching else "select", s)]
        if not self.sketching and t - self.trigger_since >= LONG_PRESS:
            self.sketching = True  # the stroke starts where the trigger went down
            return [HandEvent(self.side, "sketch_start", self.press_sample or s), HandEvent(self.side, "sketch_move", s)]
        return [HandEvent(self.side, "sketch_move", s)] if self.sketching else []


class Hands:
    """Both hands' trackers; ``update`` takes the samples of one frame."""

    def __init__(self) -> None:
        self.trackers = {side: HandTracker(side) for side in SIDES}

    def update(self, samples: list[HandSample], t: float) -> list[HandEvent]:
        events: list[HandEvent] = []
        for s in samples:
            events += self.trackers[s.side].update(s, t)
        return events

    def sample(self, side: str) -> HandSample:
        return self.trackers[side].last
