"""The VR backend: OpenXR controllers as the two hands, one render per eye, same App and renderer.

The client talks to VR through a small runtime interface, ``XrRuntime``: ``frames()`` yields one
``XrFrame`` (controller states) per display frame while the session runs, ``views(frame)`` yields the
eyes (pose, field of view, image size) with that eye's target bound, ``present(renderer)`` puts the
renderer's image into it. ``PyOpenXRRuntime`` implements it with pyopenxr (``pip install
arboretum[vr]``); tests drive ``VrSession`` with a fake. Without a runtime, ``open_runtime`` raises
``VrUnavailable`` with a clear message and the CLI falls back to the desktop.

Buttons (VRTree 3.3): grip (squeeze > 0.5), trigger (> 0.5), touchpad click, menu.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from arboretum_library.errors import ArboretumError

from .hands import HandSample

PRESS = 0.5
"""Analogue trigger / squeeze value counted as pressed."""


class VrUnavailable(ArboretumError):
    code = "vr_unavailable"


@dataclass(frozen=True, eq=False)
class ControllerState:
    """One controller as the runtime reports it."""

    side: str
    T_world_grip: np.ndarray = field(default_factory=lambda: np.eye(4))
    """(4, 4) grip pose, world (stage) frame, Z up."""
    trigger: float = 0.0
    squeeze: float = 0.0
    touchpad: tuple[float, float] = (0.0, 0.0)
    touchpad_click: bool = False
    menu: bool = False
    active: bool = True


@dataclass(frozen=True, eq=False)
class EyeView:
    T_world_eye: np.ndarray
    """(4, 4) eye pose, world frame; the eye looks down its -Z axis (OpenXR convention)."""
    fov: tuple[float, float, float, float]
    """Angles left, right, up, down in radians (left and down negative)."""
    size: tuple[int, int]


@dataclass(frozen=True)
class XrFrame:
    time: float
    """Predicted display time, seconds."""
    controllers: tuple[ControllerState, ...]


class XrRuntime(Protocol):
    def frames(self) -> Iterator[XrFrame]: ...

    def views(self, frame: XrFrame) -> Iterator[EyeView]: ...

    def present(self, renderer) -> None: ...

    def close(self) -> None: ...


def to_hand(c: ControllerState) -> HandSample:
    """A controller state as a hand sample (buttons thresholded, ray along the grip's -Z)."""
    buttons = {name for name, on in (("grip", c.squeeze > PRESS), ("trigger", c.trigger > PRESS),
                                     ("touchpad", c.touchpad_click), ("menu", c.menu)) if on}
    ray = -c.T_world_grip[:3, 2]
    scale = 2.0 ** c.touchpad[1] if "grip" in buttons else 1.0  # thumb up on the pad: up to twice the size
    return HandSample(c.side, np.asarray(c.T_world_grip, float), (float(ray[0]), float(ray[1]), float(ray[2])),
                      frozenset(buttons), c.touchpad, None, c.active, scale)


@dataclass(frozen=True)
class EyeCamera:
    """A camera from an OpenXR view (duck-types ``camera.Camera`` for the renderer)."""

    T_world_eye: np.ndarray
    fov: tuple[float, float, float, float]
    near: float = 0.05
    far: float = 100.0

    @property
    def eye(self) -> np.ndarray:
        return self.T_world_eye[:3, 3]

    def view_matrix(self) -> np.ndarray:
        return np.linalg.inv(self.T_world_eye)

    def projection_matrix(self, aspect: float | None = None) -> np.ndarray:
        """Asymmetric-frustum projection from the four fov angles (``aspect`` is ignored)."""
        left, right, up, down = (math.tan(a) for a in self.fov)
        n, f = self.near, self.far
        P = np.zeros((4, 4))
        P[0, 0], P[0, 2] = 2 / (right - left), (right + left) / (right - left)
        P[1, 1], P[1, 2] = 2 / (up - down), (up + down) / (up - down)
        P[2, 2], P[2, 3] = -(f + n) / (f - n), -2 * f * n / (f - n)
        P[3, 2] = -1.0
        return P


class VrSession:
    """Runs the App from a runtime: per frame, hands from controllers, then one render per eye."""

    def __init__(self, app, runtime: XrRuntime) -> None:
        self.app, self.runtime = app, runtime
        self.frames = 0
        self._hands: list[HandSample] = []
        app.vr_samples = lambda: self._hands

    def run(self, max_frames: int | None = None) -> int:
        for frame in self.runtime.frames():
            self._hands = [to_hand(c) for c in frame.controllers]
            self.app.update()
            for view in self.runtime.views(frame):
                self.app.renderer.render(EyeCamera(view.T_world_eye, view.fov))
                self.runtime.present(self.app.renderer)
            self.frames += 1
            if max_frames is not None and self.frames >= max_frames:
                break
        return self.frames


def open_runtime() -> XrRuntime:
    """A pyopenxr runtime, or ``VrUnavailable`` naming what is missing."""
    try:
        import xr
    except ImportError:
        raise VrUnavailable("VR needs pyopenxr: pip install 'arboretum[vr]' (or pip install pyopenxr)") from None
    try:
        probe = xr.create_instance(xr.InstanceCreateInfo(enabled_extension_names=[]))  # fails without a runtime
        xr.destroy_instance(probe)
        from .openxr_runtime import PyOpenXRRuntime

        return PyOpenXRRuntime()
    except RuntimeError as exc:  # pyopenxr's GLFW context provider
        raise VrUnavailable(f"cannot open a GL context for VR ({exc}); using the desktop instead") from None
    except xr.exception.RuntimeUnavailableError:
        raise VrUnavailable("no OpenXR runtime is installed or active (e.g. SteamVR or Monado); "
                            "using the desktop instead") from None
    except xr.exception.XrException as exc:
        raise VrUnavailable(f"OpenXR could not start a session ({exc}); using the desktop instead") from None
