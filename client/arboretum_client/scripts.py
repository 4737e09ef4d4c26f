"""Run the client from a script of input events, headless (EGL), and take screenshots.

A script is JSON (or YAML when PyYAML is installed; numbers as YAML 1.2 reads them, so ``1e-3`` is one): ``{"steps": [...]}`` or the bare list. Each step is
one input on the same code path as a window (mouse/keys into ``App.handle``; VR-style hand samples into
the hands model), followed by frames until the network worker is idle. Time is virtual: frames advance
a clock by ``1 / fps`` seconds, so long presses are reproducible.

Steps (one key each):
- ``{"mouse": [x, y]}`` / ``{"world": [x, y, z]}``: move the cursor to a pixel / to where a point projects;
- ``{"press": "left"}``, ``{"release": "left"}``, ``{"click": "left"}`` (press and release in one frame);
- ``{"key": "tab"}`` (press and release), ``{"hold": "ctrl"}``, ``{"unhold": "ctrl"}``;
- ``{"wait": seconds}``: run frames; ``{"action": "grow"}``: a panel action (see ``App.ui_action``);
- ``{"stroke": [[x, y, z], ...]}``: draw a stroke with the left mouse button through world points;
- ``{"drag": {"from": [x, y, z], "to": [x, y, z], "button": "right"}}``: a grip drag between points;
- ``{"hands": [{"side": "left", "position": [x, y, z], "buttons": ["grip"]}, ...]}``: VR-style hand
  samples (kept until ``{"hands": null}``);
- ``{"select": ["lobe:2", "lobe:5"]}``: select by pick name (as trigger clicks would);
- ``{"view": "iso"}``: frame the scene from a named view; ``{"screenshot": "out.png"}``;
- ``{"reference": "photo.png"}`` (or ``{"image": ..., "height": metres}``, or null to remove it): show a
  reference image behind the tree (``App.set_reference``; the action ``reference`` hides/shows it).

Every step is checked before the first runs (``script_check``); a bad one is an ``InputError`` naming
the step number and key. Top-level keys besides ``steps``: ``reference`` (an image path, relative to the script's folder) and
``reference_height`` (metres), read by ``arboretum client`` like ``--reference`` / ``--reference-height``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from arboretum_library.errors import InputError

from .camera import fit_camera
from .input.desktop import Key, MouseButton, MouseMove
from .input.hands import LONG_PRESS, HandSample
from .script_check import check_steps


def load_script(path: str | Path) -> dict:
    """Read a script file (JSON, or YAML by suffix) into ``{"steps": [...]}``."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"script {path}: cannot read it ({exc.strerror})") from None
    try:
        if path.suffix in (".yaml", ".yml"):
            import yaml

            from arboretum_library.yaml12 import with_yaml12_numbers

            data = yaml.load(text, Loader=with_yaml12_numbers(yaml.SafeLoader))
        else:
            data = json.loads(text)
    except Exception as exc:
        raise InputError(f"script {path}: not valid {path.suffix[1:] or 'JSON'} ({exc})") from None
    if isinstance(data, list):
        data = {"steps": data}
    if not isinstance(data, dict) or not isinstance(data.get("steps"), list):
        raise InputError(f"script {path}: expected a list of steps or {{'steps': [...]}}")
    return data


def script_reference(path: str | Path) -> tuple[str | None, float | None]:
    """The script's top-level ``reference`` image path (resolved against the script's folder) and
    ``reference_height``, each None when absent."""
    data = load_script(path)
    ref, height = data.get("reference"), data.get("reference_height")
    if ref is not None and not isinstance(ref, str):
        raise InputError(f"script {path}: 'reference' must be an image path, got {ref!r}")
    if height is not None and not isinstance(height, int | float):
        raise InputError(f"script {path}: 'reference_height' must be a number of metres, got {height!r}")
    return (str(Path(path).parent / ref) if ref else None), (float(height) if height is not None else None)


class ScriptRunner:
    """Drives an ``App`` (whose clock is ``self.now``) through script steps."""

    def __init__(self, app, fps: float = 30.0, base: Path | None = None) -> None:
        self.app, self.dt, self.now = app, 1.0 / fps, 0.0
        self.base = base or Path(".")
        self.shots: list[Path] = []
        self.hand_samples: list[HandSample] | None = None

    def clock(self) -> float:
        return self.now

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            self.now += self.dt
            self.app.frame()

    def settle(self) -> None:
        """Frames until no network job runs (scripts may wait; the interactive loop never does)."""
        self.tick()
        for _ in range(200):
            if self.app.worker.wait_idle(30.0):
                self.tick()
                if self.app.worker.idle():
                    return
        raise InputError("script: the server did not answer within the time limit")

    def to_pixel(self, p) -> tuple[float, float]:
        px = self.app.desktop.camera.project(np.asarray(p, float)[None], self.app.size)[0]
        return float(px[0]), float(px[1])

    def run(self, steps: list[dict]) -> list[Path]:
        """Check every step (``script_check.check_steps``), then run them; ``InputError`` naming the
        step for a malformed one, a ``choose:`` of an example the library does not have, or a
        ``select`` of a name that is not in the scene."""
        check_steps(steps)
        for i, step in enumerate(steps):
            (name, arg), = step.items()
            getattr(self, f"_step_{name}")(arg)
            self.settle()
            problem = self._after(name, arg)
            if problem:
                raise InputError(f"script step {i + 1} ({name}): {problem}")
        return self.shots

    def _after(self, name: str, arg) -> str | None:
        """What went wrong with a step that only running it shows, or None."""
        s = self.app.state
        if name == "action" and arg.startswith("choose:") and arg[7:] not in s.examples:
            return f"{arg}: no such example ({s.status})"
        if name == "select":
            scene = set(self.app.names.values())
            for n in [arg] if isinstance(arg, str) else arg:
                if n not in scene and not any(m.startswith(n + "/") for m in scene):
                    # an empty scene: say why, e.g. a refinement draft that could not be opened
                    shown = f"e.g. {', '.join(sorted(scene)[:8])}" if scene else f"nothing is pickable now; {s.status}"
                    return f"nothing named {n!r} in the scene ({shown})"
        return None

    # -- steps -------------------------------------------------------------------------------------
    def _step_mouse(self, xy) -> None:
        self.app.handle(MouseMove(float(xy[0]), float(xy[1])))

    def _step_world(self, p) -> None:
        self.app.handle(MouseMove(*self.to_pixel(p)))

    def _step_press(self, button: str) -> None:
        self.app.handle(MouseButton(button, True))

    def _step_release(self, button: str) -> None:
        self.app.handle(MouseButton(button, False))

    def _step_click(self, button: str) -> None:
        self.app.handle(MouseButton(button, True))
        self.tick()
        self.app.handle(MouseButton(button, False))

    def _step_key(self, name: str) -> None:
        self.app.handle(Key(name, True))
        self.tick()
        self.app.handle(Key(name, False))

    def _step_hold(self, name: str) -> None:
        self.app.handle(Key(name, True))

    def _step_unhold(self, name: str) -> None:
        self.app.handle(Key(name, False))

    def _step_wait(self, seconds: float) -> None:
        self.tick(max(int(round(float(seconds) / self.dt)), 1))

    def _step_action(self, action: str) -> None:
        self.app.ui_action(action)

    def _step_select(self, names) -> None:
        """Select pick names directly ('inst:NAME', 'inst:NAME/lobe:2', 'lobe:3'), as a trigger click would."""
        self.app.state.selection = [names] if isinstance(names, str) else list(names)
        self.app.state.touch_scene()

    def _step_view(self, view: str) -> None:
        self.app.desktop.camera = fit_camera(self.app.bounds, view, self.app.size[0] / self.app.size[1])
        self.app.clear_panel()  # keep the tree clear of the side panel

    def _step_stroke(self, points) -> None:
        pts = np.asarray(points, float).reshape(-1, 3)
        self._step_world(pts[0])
        self.app.handle(MouseButton("left", True))
        self.tick(int(LONG_PRESS / self.dt) + 2)
        for p in pts[1:]:
            self._step_world(p)
            self.tick()
        self.app.handle(MouseButton("left", False))

    def _step_drag(self, spec: dict) -> None:
        button = spec.get("button", "right")
        self._step_world(spec["from"])
        self.tick()
        self.app.handle(MouseButton(button, True))
        self.tick()
        a, b = np.asarray(spec["from"], float), np.asarray(spec["to"], float)
        for t in np.linspace(0, 1, 6)[1:]:
            self._step_world(a + t * (b - a))
            self.tick()
        self.app.handle(MouseButton(button, False))

    def _step_hands(self, specs) -> None:
        if specs is None:
            self.app.vr_samples = None
            return
        samples = []
        for spec in specs:
            T = np.eye(4)
            T[:3, 3] = spec["position"]
            samples.append(HandSample(spec["side"], T, buttons=frozenset(spec.get("buttons", ()))))
        self.app.vr_samples = lambda: samples

    def _step_reference(self, spec) -> None:
        from .app import load_reference, reference_billboard

        if spec is None:
            self.app.set_reference(None)
            return
        path, height = (spec, 1.0) if isinstance(spec, str) else (spec["image"], float(spec.get("height", 1.0)))
        self.app.set_reference(reference_billboard(load_reference(self.base / path), height))

    def _step_screenshot(self, path: str) -> None:
        from .headless import save_png

        self.tick()
        out = self.base / path
        save_png(self.app.renderer.read()[..., :3], out)
        self.shots.append(out)
