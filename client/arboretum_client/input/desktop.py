"""The desktop backend: the mouse ray is one hand, a keyboard modifier switches to the other; cameras.

Mouse: left button = trigger (click selects, hold draws a sketch), right button = grip (drag moves;
with Shift, horizontal motion turns about the vertical axis; the wheel scales what is held), middle
button (or Alt + left) orbits,
Shift + middle pans, the wheel zooms. Holding Ctrl routes the mouse to the left (blue) hand instead of
the right (red) one; the other hand stays where it was. Keys T and M are the touchpad and menu buttons
of the active hand. F toggles the fly camera (W/A/S/D/Q/E move, the middle button looks around).

Input arrives as small records (``MouseMove``, ``MouseButton``, ``Scroll``, ``Key``) from glfw callbacks
or from a script, so windows and scripts share one code path.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from arboretum_client.assembly_view import rot_z
from arboretum_client.camera import Camera

from .hands import LEFT, RIGHT, HandSample

GRIP_SCALE = 100.0
"""The wheel scales what a hand holds by at most this factor up or down in one grab."""


@dataclass(frozen=True)
class MouseMove:
    x: float
    y: float


@dataclass(frozen=True)
class MouseButton:
    button: str
    """'left', 'right' or 'middle'."""
    pressed: bool


@dataclass(frozen=True)
class Scroll:
    dy: float


@dataclass(frozen=True)
class Key:
    name: str
    """glfw-style key name: 'a', 'tab', 'delete', 'f5', ... (lower case)."""
    pressed: bool = True


def cursor_ray(camera: Camera, size: tuple[int, int], x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
    """World ray (origin (3,), unit direction (3,)) through output pixel (x right, y down)."""
    w, h = size
    inv = np.linalg.inv(camera.projection_matrix(w / h) @ camera.view_matrix())
    ndc = np.array([2 * x / w - 1, 1 - 2 * y / h])
    near = inv @ np.array([ndc[0], ndc[1], -1.0, 1.0])
    far = inv @ np.array([ndc[0], ndc[1], 1.0, 1.0])
    a, b = near[:3] / near[3], far[:3] / far[3]
    d = b - a
    return camera.eye, d / np.linalg.norm(d)


class DesktopInput:
    """Keeps the camera and two hands from mouse/keyboard records; ``samples()`` each frame."""

    def __init__(self, camera: Camera, size: tuple[int, int]) -> None:
        self.camera, self.size = camera, size
        self.mouse = (size[0] / 2, size[1] / 2)
        self.buttons: set[str] = set()
        self.mods: set[str] = set()
        self.fly = False
        self.keys_down: set[str] = set()
        self.hand_buttons = {LEFT: set(), RIGHT: set()}
        self.hand_pose = {LEFT: np.eye(4), RIGHT: np.eye(4)}
        self.hand_ray = {LEFT: (0.0, 0.0, -1.0), RIGHT: (0.0, 0.0, -1.0)}
        self.hand_pixel: dict[str, tuple[float, float] | None] = {LEFT: None, RIGHT: None}
        self.yaw = {LEFT: 0.0, RIGHT: 0.0}
        self.grip_scale = {LEFT: 1.0, RIGHT: 1.0}
        self.key_presses: list[str] = []
        """Key names pressed since the last ``take_keys`` (with 'ctrl+' / 'shift+' prefixes)."""
        self._place(RIGHT)

    @property
    def active(self) -> str:
        return LEFT if "ctrl" in self.mods else RIGHT

    def handle(self, event) -> None:
        if isinstance(event, MouseMove):
            self._move(event.x, event.y)
        elif isinstance(event, MouseButton):
            self._button(event.button, event.pressed)
        elif isinstance(event, Scroll) and "grip" in self.hand_buttons[self.active]:
            # scale what the hand holds, within GRIP_SCALE of where the grab began (unbounded, 70 wheel
            # steps left the model's scale range and the preview raised in the main loop)
            g = self.grip_scale[self.active] * 1.1 ** event.dy
            self.grip_scale[self.active] = min(max(g, 1.0 / GRIP_SCALE), GRIP_SCALE)
        elif isinstance(event, Scroll):
            self.camera = dataclasses.replace(self.camera, distance=max(self.camera.distance * 0.9 ** event.dy, 0.05))
        elif isinstance(event, Key):
            self._key(event.name, event.pressed)

    def _move(self, x: float, y: float) -> None:
        dx, dy = x - self.mouse[0], y - self.mouse[1]
        self.mouse = (x, y)
        if "middle" in self.buttons or ("left" in self.buttons and "alt" in self.mods):
            if "shift" in self.mods:
                self._pan(dx, dy)
            elif self.fly:
                self._look(dx, dy)
            else:
                self.camera = self.camera.orbit(-dx * 0.3, dy * 0.3)
            return
        side = self.active
        if "grip" in self.hand_buttons[side] and "shift" in self.mods:
            self.yaw[side] += dx * 0.01  # turn about +Z, keep the position
            self.hand_pose[side][:3, :3] = rot_z(self.yaw[side])
            return
        self._place(side)

    def _place(self, side: str) -> None:
        """Put ``side``'s hand on the cursor ray, at the depth of the camera target."""
        origin, d = cursor_ray(self.camera, self.size, *self.mouse)
        forward = np.asarray(self.camera.target) - self.camera.eye
        depth = float(np.dot(forward, forward) / max(np.dot(forward, d), 1e-6))
        T = np.eye(4)
        T[:3, :3] = rot_z(self.yaw[side])
        T[:3, 3] = origin + d * depth
        self.hand_pose[side], self.hand_ray[side], self.hand_pixel[side] = T, tuple(d), self.mouse

    def _pan(self, dx: float, dy: float) -> None:
        V = self.camera.view_matrix()
        scale = self.camera.distance * 2 * math.tan(math.radians(self.camera.fov_y) / 2) / self.size[1]
        move = (-dx * V[0, :3] + dy * V[1, :3]) * scale
        self.camera = dataclasses.replace(self.camera, target=tuple(np.asarray(self.camera.target) + move))

    def _look(self, dx: float, dy: float) -> None:
        """Fly camera: turn about the eye (the target moves, the eye stays)."""
        eye = self.camera.eye
        turned = self.camera.orbit(dx * 0.2, -dy * 0.2)
        target = eye - turned.distance * (turned.eye - np.asarray(turned.target)) / turned.distance
        self.camera = dataclasses.replace(turned, target=tuple(target))

    def _button(self, button: str, pressed: bool) -> None:
        (self.buttons.add if pressed else self.buttons.discard)(button)
        if button == "left" and "alt" in self.mods:
            return
        name = {"left": "trigger", "right": "grip"}.get(button)
        if name is None:
            return
        side = self.active
        if pressed:
            self._place(side)
            self.hand_buttons[side].add(name)
            if name == "grip":
                self.grip_scale[side] = 1.0
        else:
            for s in (LEFT, RIGHT):
                self.hand_buttons[s].discard(name)

    def _key(self, name: str, pressed: bool) -> None:
        if name in ("ctrl", "shift", "alt"):
            (self.mods.add if pressed else self.mods.discard)(name)
            return
        (self.keys_down.add if pressed else self.keys_down.discard)(name)
        hand_key = {"t": "touchpad", "m": "menu"}.get(name)
        if hand_key:
            (self.hand_buttons[self.active].add if pressed else self.hand_buttons[self.active].discard)(hand_key)
        elif pressed:
            prefix = "".join(f"{m}+" for m in ("ctrl", "shift") if m in self.mods)
            self.key_presses.append(prefix + name)
            if name == "f" and not prefix:
                self.fly = not self.fly

    def take_keys(self) -> list[str]:
        keys, self.key_presses = self.key_presses, []
        return keys

    def advance(self, dt: float) -> None:
        """Fly camera movement for held W/A/S/D/Q/E over ``dt`` seconds."""
        if not self.fly:
            return
        V = self.camera.view_matrix()
        axes = {"w": -V[2, :3], "s": V[2, :3], "d": V[0, :3], "a": -V[0, :3], "e": np.array([0, 0, 1.0]),
                "q": np.array([0, 0, -1.0])}
        move = sum((axes[k] for k in self.keys_down if k in axes), np.zeros(3))
        if np.any(move):
            step = move * self.camera.distance * 0.8 * dt
            self.camera = dataclasses.replace(self.camera, target=tuple(np.asarray(self.camera.target) + step))

    def samples(self) -> list[HandSample]:
        return [HandSample(side, self.hand_pose[side].copy(), self.hand_ray[side],
                           frozenset(self.hand_buttons[side]), pixel=self.hand_pixel[side],
                           tracked=self.hand_pixel[side] is not None, scale=self.grip_scale[side])
                for side in (LEFT, RIGHT)]
