"""glfw callbacks -> the desktop input records the App handles (the only glfw input code).

Cursor positions come in window units and are scaled to framebuffer pixels (HiDPI) by a scale asked of
glfw once and again on each framebuffer size change (resize, maximise, a move to a screen of another
density), never per mouse move; that change also resizes the renderer and the UI (``App.resize``)."""

from __future__ import annotations

from .input.desktop import Key, MouseButton, MouseMove, Scroll
from .net import USER_ERRORS
from .tools.actions import describe_error

SPECIAL = {"TAB": "tab", "ENTER": "enter", "KP_ENTER": "enter", "ESCAPE": "escape", "BACKSPACE": "backspace",
           "DELETE": "delete", "SPACE": "space", "LEFT_CONTROL": "ctrl", "RIGHT_CONTROL": "ctrl",
           "LEFT_SHIFT": "shift", "RIGHT_SHIFT": "shift", "LEFT_ALT": "alt", "RIGHT_ALT": "alt",
           "LEFT_BRACKET": "[", "RIGHT_BRACKET": "]", "SLASH": "/", "F5": "f5", "F9": "f9"}
BUTTONS = {0: "left", 1: "right", 2: "middle"}


def key_table() -> dict[int, str]:
    """glfw key code -> our key name, for the special keys."""
    import glfw

    return {getattr(glfw, f"KEY_{name}"): value for name, value in SPECIAL.items() if hasattr(glfw, f"KEY_{name}")}


def handle_safely(app, event) -> None:
    """``app.handle(event)``, with a failure the user caused put in the status line: an exception
    escaping a glfw callback would be re-raised by ``glfw.poll_events`` and end the client."""
    try:
        app.handle(event)
    except USER_ERRORS as exc:
        app.state.errors.append(describe_error(exc))
        app.state.say(f"failed: {describe_error(exc)}")


def cursor_scale(window) -> tuple[float, float]:
    """Framebuffer pixels per window unit (x, y): 1 on most displays, 2 on a HiDPI/Retina one."""
    import glfw

    (ww, wh), (fw, fh) = glfw.get_window_size(window), glfw.get_framebuffer_size(window)
    return (fw / ww if ww > 0 else 1.0), (fh / wh if wh > 0 else 1.0)


def install_callbacks(window, app) -> None:
    """Route glfw's mouse, scroll and key callbacks of ``window`` into ``app.handle`` (cursor positions
    mapped from window units to framebuffer pixels by ``cursor_scale``, kept from the last framebuffer
    size change), and framebuffer size changes into ``app.resize``."""
    import glfw

    table = key_table()
    scale = [cursor_scale(window)]

    def on_key(_w, key, scancode, action, _mods):
        if action == glfw.REPEAT:
            return
        name = table.get(key) or (glfw.get_key_name(key, scancode) or "").lower()
        if name:
            handle_safely(app, Key(name, action == glfw.PRESS))

    def on_cursor(_w, x, y):
        sx, sy = scale[0]
        handle_safely(app, MouseMove(float(x) * sx, float(y) * sy))

    def on_framebuffer(w, width, height):
        if width > 0 and height > 0:  # 0 x 0 while minimised: keep the last size (and scale)
            scale[0] = cursor_scale(w)
            app.resize((int(width), int(height)))

    glfw.set_cursor_pos_callback(window, on_cursor)
    glfw.set_mouse_button_callback(
        window, lambda _w, b, action, _m: handle_safely(app, MouseButton(BUTTONS.get(b, "other"), action == glfw.PRESS)))
    glfw.set_scroll_callback(window, lambda _w, _dx, dy: handle_safely(app, Scroll(float(dy))))
    glfw.set_key_callback(window, on_key)
    glfw.set_framebuffer_size_callback(window, on_framebuffer)
