"""The interactive client's frame: input -> hands -> tools -> scene -> renderer, never waiting on the net.

``App`` owns the state, the network worker, the interaction tools and a ``Renderer`` (of a glfw window
or of an EGL context: the same code path for windows, scripts and tests). One call to ``frame`` does:

1. drain finished network jobs (callbacks update the state);
2. turn this frame's hand samples (desktop or VR) into events, find what each hand touches (the ID
   buffer under the desktop cursor, or the nearest item to a VR touch ball), and hand events to tools;
3. rebuild the scene only when ``state.scene_version`` changed, the overlay only when the hands or
   strokes moved, the UI image only when the state or a job's progress changed;
4. issue the frame's draw calls.

Per-frame Python work is O(draw calls): nothing iterates over vertices unless something changed.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .camera import Camera, fit_camera
from .input.desktop import DesktopInput, Key, MouseButton, MouseMove
from .input.hands import HAND_COLORS, LEFT, RIGHT, SIDES, Hands, HandSample
from .net import Worker
from .overlay import overlay_key, overlay_scene
from .scene import Billboard
from .scene_build import to_rgba8
from .session_port import SessionPort
from .tools.actions import Actions
from .tools.interaction import Interaction
from .tools.state import MODELING, REFINEMENT, ClientState
from .tools.view import TouchIndex, build_scene
from .ui.layout import PANEL_X, draw_ui, panel_width, ui_key
from .ui.widgets import Canvas
from .ui_actions import run_action

TOUCH_RADIUS = 0.06
"""Metres: a VR touch ball this close to an item touches it."""
REFERENCE_BEHIND = 0.6
"""How far behind the origin (+Y, away from the front camera) a reference image stands, in units of its height."""


def load_reference(path: str | Path) -> np.ndarray:
    """A PNG/JPEG (anything pillow reads) as an (H, W, 4) uint8 RGBA array, top row first."""
    from PIL import Image, UnidentifiedImageError

    from arboretum_library.errors import InputError

    try:
        with Image.open(path) as im:
            return to_rgba8(im)
    except FileNotFoundError:
        raise InputError(f"reference image {path}: no such file") from None
    except (OSError, UnidentifiedImageError) as exc:
        raise InputError(f"reference image {path}: cannot read it as an image ({exc})") from None


def reference_billboard(image: np.ndarray, height: float = 1.0) -> Billboard:
    """The reference ``image`` (H, W, 4) standing on the ground (z = 0) behind the origin, facing the
    front camera (-Y), ``height`` metres tall, as wide as the image's aspect makes it."""
    from arboretum_library.errors import InputError

    if not (np.isfinite(height) and height > 0):
        raise InputError(f"--reference-height: must be a positive number of metres, got {height}")
    h, w = image.shape[:2]
    return Billboard(image, (0.0, REFERENCE_BEHIND * height, height / 2), height * w / h, height)


class Scan(NamedTuple):
    """What ``--scan`` gives refinement: the points (N, 3) and labels, the file's name (the committed
    examples' source), the species and ``DecomposeOptions`` fields (``--main``, ``--lobes``)."""

    points: np.ndarray
    labels: np.ndarray | None
    name: str = "scan"
    species: str = "unknown"
    options: dict = {}


class App:
    """One client: state, worker, tools, desktop input and a renderer."""

    def __init__(self, renderer, port_factory: Callable[[], SessionPort], out_dir: str | Path = ".",
                 clock: Callable[[], float] = time.monotonic, ui: bool = True,
                 scan: tuple | None = None,  # a Scan (or its first fields) of --scan, refined on Tab
                 reference: Billboard | None = None) -> None:
        self.renderer, self.size = renderer, renderer.size
        self.reference, self.show_reference = reference, True
        """A reference image drawn behind the tree (``reference_billboard``); key B shows/hides it."""
        self.clock, self.out_dir, self.ui_enabled, self.scan = clock, Path(out_dir), ui, scan
        self.state = ClientState()
        self.worker = Worker(port_factory)
        self.actions = Actions(self.state, self.worker, clock)
        self.interaction = Interaction(self.state, self.actions)
        self.camera = Camera(target=(0.0, 0.0, 0.8), distance=4.0)
        self.desktop = DesktopInput(self.camera, self.size)
        self.hands = Hands()
        self.touched: dict[str, str | None] = {LEFT: None, RIGHT: None}
        self.touch = TouchIndex(np.zeros((0, 3)), np.zeros(0, np.int32))
        self.names: dict[int, str] = {}
        self.bounds = np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 2.0]])
        """(2, 3) bounds of the scene drawn now."""
        self.canvas: Canvas | None = None
        self._uploaded, self._overlay, self._ui, self._framed = -1, None, None, False
        self._last_pixel: dict[str, tuple | None] = {LEFT: None, RIGHT: None}
        self.vr_samples: Callable[[], list[HandSample]] | None = None
        """Set by the VR backend: hand samples come from the headset instead of the mouse."""

    def start(self) -> None:
        self.actions.refresh_library()
        self.actions.sync()

    # -- input -------------------------------------------------------------------------------------
    def handle(self, event) -> None:
        """A desktop input record (mouse, scroll, key); panels get first refusal."""
        s = self.state
        if isinstance(event, MouseButton) and event.button == "left" and self.canvas is not None:
            x, y = self.desktop.mouse
            if self.canvas.covers(x, y):
                if event.pressed:
                    self.ui_action(self.canvas.hit(x, y) or "noop")
                return
        if isinstance(event, Key) and s.search_focus and event.pressed and event.name not in ("ctrl", "shift", "alt"):
            self._type(event.name)
            return
        self.desktop.handle(event)

    def _type(self, name: str) -> None:
        s = self.state
        if name == "enter":
            s.search_focus = False
            self.actions.search(s.query)
        elif name == "escape":
            s.search_focus = False
        elif name == "backspace":
            s.query = s.query[:-1]
        elif name == "space":
            s.query += " "
        elif len(name) == 1:
            s.query += name
        s.ui_version += 1

    def ui_action(self, action: str) -> None:
        """Run a panel button's action (also used by shortcuts and scripts): ``ui_actions.run_action``."""
        run_action(self, action)
        self.state.ui_version += 1

    def toggle_mode(self) -> None:
        s = self.state
        s.mode = MODELING if s.mode == REFINEMENT else REFINEMENT
        s.clear_picks()
        if s.mode == REFINEMENT and s.draft is None:
            # no scan: the offline session refines its demo tree; a server refuses (said so by refine_open)
            scan = Scan(*self.scan) if self.scan is not None else Scan(np.zeros((0, 3)), None)
            self.actions.refine_open(scan.points, scan.labels, scan.species, scan.name, scan.options)
        self._framed = False
        s.touch_scene()

    def toggle_reference(self) -> None:
        """Show or hide the reference image (a scene re-upload; its texture stays cached)."""
        self.show_reference = not self.show_reference
        self.state.touch_scene()

    def set_reference(self, reference: Billboard | None) -> None:
        self.reference, self.show_reference = reference, True
        self.state.touch_scene()

    KEYS = {"b": "reference", "ctrl+z": "undo", "ctrl+y": "redo", "delete": "menu", "enter": "touchpad", "g": "grow", "x": "export",
            "ctrl+s": "save", "ctrl+o": "load", "tab": "mode", "p": "toggle:show_points", "o": "toggle:show_all",
            "n": "focus:+", "]": "density:+", "[": "density:-", "/": "search:focus", "c": "commit"}

    def _shortcuts(self) -> None:
        for key in self.desktop.take_keys():
            if key == "escape":
                self.state.clear_picks()
            elif key in self.KEYS:
                self.ui_action(self.KEYS[key])

    # -- frame -------------------------------------------------------------------------------------
    def update(self, dt: float = 1 / 60) -> list:
        """Steps 1-3 of a frame (everything but drawing); returns the hand events handled."""
        now = self.clock()
        self.worker.drain()
        self.desktop.advance(dt)
        samples = self.vr_samples() if self.vr_samples is not None else self.desktop.samples()
        events = self.hands.update(samples, now)
        self._update_touch(samples)
        for ev in events:
            self.interaction.handle(ev, self.touched[ev.side])
        self._shortcuts()
        self._sync_scene(now)
        self._sync_overlay(samples)
        self._sync_ui()
        self.renderer.set_highlight(tuple(self._touched_id(s) for s in SIDES), (HAND_COLORS[LEFT], HAND_COLORS[RIGHT]))
        return events

    def frame(self, camera=None):
        """Update and issue one frame; returns the renderer's stats."""
        self.update()
        return self.renderer.render(camera or self.desktop.camera)

    def _touched_id(self, side: str) -> int | None:
        name = self.touched[side]
        return next((k for k, v in self.names.items() if v == name), None) if name else None

    def _update_touch(self, samples: list[HandSample]) -> None:
        for s in samples:
            if self.interaction.drags.get(s.side) is not None:
                continue  # keep touching what is being dragged
            if s.pixel is not None:
                if s.pixel != self._last_pixel[s.side] and self.renderer._camera is not None:
                    self._last_pixel[s.side] = s.pixel
                    self.touched[s.side] = self.names.get(self.renderer.pick(int(s.pixel[0]), int(s.pixel[1])) or 0)
            elif s.tracked:
                pid = self.touch.nearest(s.position, TOUCH_RADIUS)
                self.touched[s.side] = self.names.get(pid or 0)

    def _sync_scene(self, now: float) -> None:
        s = self.state
        flashing = any(t > now for t in s.merged_flash.values())
        if s.scene_version == self._uploaded and not flashing:
            return
        if not flashing:
            s.merged_flash.clear()
        scene, self.touch = build_scene(s, now)
        has_items = bool(scene.items)
        if self.reference is not None and self.show_reference:
            scene = dataclasses.replace(scene, items=(*scene.items, self.reference))
        self.renderer.upload(scene)
        self.names, self._uploaded, self.bounds = scene.names, s.scene_version, scene.bounds()
        self._last_pixel = {LEFT: None, RIGHT: None}
        if not self._framed and has_items:  # framed on the tree (and the reference) once a tree comes
            self.desktop.camera = fit_camera(scene.bounds(), "iso", self.size[0] / self.size[1])
            self.clear_panel()
            self._framed = True

    def _sync_overlay(self, samples: list[HandSample]) -> None:
        key = overlay_key(self.state, samples, self.interaction.drags)
        if key != self._overlay:
            self._overlay = key
            self.renderer.upload_overlay(overlay_scene(self.state, samples, self.interaction.drags,
                                                       self.desktop.camera.distance))

    def _sync_ui(self) -> None:
        if not self.ui_enabled:
            return
        key = ui_key(self.state, self.worker.running)
        if key != self._ui:
            self._ui = key
            self.canvas = draw_ui(self.size, self.state, self.worker.running)
            self.renderer.set_ui_image(self.canvas.rgba())

    def clear_panel(self) -> None:
        """Pan the camera by half the side panel's width (and margin) so the tree is clear of it."""
        width = panel_width(self.size) if self.ui_enabled else 0
        if width:
            self.desktop._pan((width + PANEL_X) / 2, 0.0)

    def resize(self, size: tuple[int, int]) -> None:
        """The output (window framebuffer) is now ``size`` pixels: new render targets, the camera's
        aspect follows (it is taken from the size each frame), the desktop cursor ray and the panels
        are laid out again."""
        size = (int(size[0]), int(size[1]))
        if size == self.size:
            return
        self.renderer.resize(size)
        self.size = self.desktop.size = size
        self._ui, self._last_pixel = None, {LEFT: None, RIGHT: None}

    def move_mouse(self, x: float, y: float) -> None:
        self.handle(MouseMove(x, y))

    def close(self) -> None:
        self.worker.close()
