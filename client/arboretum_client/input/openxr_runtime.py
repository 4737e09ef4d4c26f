"""``XrRuntime`` over pyopenxr: session, swapchains and frame loop from ``xr.utils.gl.ContextObject``
(GLFW offscreen context), controllers through one action set.

Not exercised by the test suite (no OpenXR runtime can be installed here, see FACTS.md); the logic
that uses it (``VrSession``) is tested against a fake runtime. OpenXR's stage space is Y up; poses are
turned into our Z-up world with ``YUP_TO_ZUP``.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator

import numpy as np

from .hands import LEFT, RIGHT
from .openxr import ControllerState, EyeView, XrFrame

YUP_TO_ZUP = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
"""(4, 4) OpenXR stage (Y up, -Z forward) -> Arboretum world (Z up)."""
BINDINGS = {
    "/interaction_profiles/htc/vive_controller": {
        "grip_pose": "input/grip/pose", "trigger": "input/trigger/value", "squeeze": "input/squeeze/click",
        "touchpad": "input/trackpad", "touchpad_click": "input/trackpad/click", "menu": "input/menu/click"},
    "/interaction_profiles/khr/simple_controller": {
        "grip_pose": "input/grip/pose", "trigger": "input/select/click", "menu": "input/menu/click"},
}


def pose_matrix(pose) -> np.ndarray:
    """(4, 4) world (Z up) matrix of an ``xr.Posef``."""
    x, y, z, w = pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (pose.position.x, pose.position.y, pose.position.z)
    return YUP_TO_ZUP @ T


class PyOpenXRRuntime:
    """Creates the OpenXR instance at once (raising ``RuntimeUnavailableError`` without a runtime)."""

    def __init__(self) -> None:
        import xr
        from xr.utils.gl import ContextObject
        from xr.utils.gl.glfw_util import GLFWOffscreenContextProvider

        self.xr = xr
        self._provider = GLFWOffscreenContextProvider()
        info = xr.InstanceCreateInfo(enabled_extension_names=[xr.KHR_OPENGL_ENABLE_EXTENSION_NAME])
        self.context = ContextObject(context_provider=self._provider, instance_create_info=info)
        self.context.__enter__()
        self._make_actions()

    def _make_actions(self) -> None:
        xr, ctx = self.xr, self.context
        self.hands = [xr.string_to_path(ctx.instance, f"/user/hand/{s}") for s in (LEFT, RIGHT)]
        aset = xr.create_action_set(ctx.instance, xr.ActionSetCreateInfo(action_set_name="arboretum",
                                                                          localized_action_set_name="Arboretum"))
        kinds = {"grip_pose": xr.ActionType.POSE_INPUT, "trigger": xr.ActionType.FLOAT_INPUT,
                 "squeeze": xr.ActionType.FLOAT_INPUT, "touchpad": xr.ActionType.VECTOR2F_INPUT,
                 "touchpad_click": xr.ActionType.BOOLEAN_INPUT, "menu": xr.ActionType.BOOLEAN_INPUT}
        paths = (xr.Path * 2)(*self.hands)
        self.actions = {name: xr.create_action(aset, xr.ActionCreateInfo(
            action_type=kind, action_name=name, localized_action_name=name, count_subaction_paths=2,
            subaction_paths=paths)) for name, kind in kinds.items()}
        for profile, table in BINDINGS.items():
            suggested = [xr.ActionSuggestedBinding(self.actions[a], xr.string_to_path(ctx.instance, f"/user/hand/{s}/{p}"))
                         for a, p in table.items() for s in (LEFT, RIGHT)]
            xr.suggest_interaction_profile_bindings(ctx.instance, xr.InteractionProfileSuggestedBinding(
                interaction_profile=xr.string_to_path(ctx.instance, profile),
                count_suggested_bindings=len(suggested),
                suggested_bindings=(xr.ActionSuggestedBinding * len(suggested))(*suggested)))
        self.spaces = [xr.create_action_space(ctx.session, xr.ActionSpaceCreateInfo(
            action=self.actions["grip_pose"], subaction_path=h)) for h in self.hands]
        ctx.action_sets.append(aset)
        self.action_set = aset

    def _controllers(self, time) -> tuple[ControllerState, ...]:
        xr, ctx = self.xr, self.context
        active = xr.ActiveActionSet(self.action_set, xr.NULL_PATH)
        xr.sync_actions(ctx.session, xr.ActionsSyncInfo(count_active_action_sets=1,
                                                        active_action_sets=ctypes.pointer(active)))
        out = []
        for side, hand, space in zip((LEFT, RIGHT), self.hands, self.spaces):
            def get(name, fn, hand=hand):
                return fn(ctx.session, xr.ActionStateGetInfo(action=self.actions[name], subaction_path=hand))
            loc = xr.locate_space(space, ctx.space, time)
            tracked = bool(loc.location_flags & xr.SPACE_LOCATION_POSITION_VALID_BIT)
            pad = get("touchpad", xr.get_action_state_vector2f).current_state
            out.append(ControllerState(
                side, pose_matrix(loc.pose) if tracked else np.eye(4),
                get("trigger", xr.get_action_state_float).current_state,
                get("squeeze", xr.get_action_state_float).current_state, (pad.x, pad.y),
                bool(get("touchpad_click", xr.get_action_state_boolean).current_state),
                bool(get("menu", xr.get_action_state_boolean).current_state), tracked))
        return tuple(out)

    def frames(self) -> Iterator[XrFrame]:
        for state in self.context.frame_loop():
            t = state.predicted_display_time
            self._state = state
            yield XrFrame(float(t) * 1e-9, self._controllers(t))

    def views(self, frame: XrFrame) -> Iterator[EyeView]:
        for view in self.context.view_loop(self._state):
            f = view.fov
            sc = self.context.swapchains[0]
            yield EyeView(pose_matrix(view.pose), (f.angle_left, f.angle_right, f.angle_up, f.angle_down),
                          (sc.width, sc.height))

    def present(self, renderer) -> None:
        renderer.present()  # into the swapchain image the context object bound for this eye

    def close(self) -> None:
        self.context.__exit__(None, None, None)
