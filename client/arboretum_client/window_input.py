"""glfw callbacks -> the desktop input records the App handles (the only glfw input code)."""

from __future__ import annotations

from .input.desktop import Key, MouseButton, MouseMove, Scroll

SPECIAL = {"TAB": "tab", "ENTER": "enter", "KP_ENTER": "enter", "ESCAPE": "escape", "BACKSPACE": "backspace",
           "DELETE": "delete", "SPACE": "space", "LEFT_CONTROL": "ctrl", "RIGHT_CONTROL": "ctrl",
           "LEFT_SHIFT": "shift", "RIGHT_SHIFT": "shift", "LEFT_ALT": "alt", "RIGHT_ALT": "alt",
           "LEFT_BRACKET": "[", "RIGHT_BRACKET": "]", "SLASH": "/", "F5": "f5", "F9": "f9"}
BUTTONS = {0: "left", 1: "right", 2: "middle"}


def key_table() -> dict[int, str]:
    """glfw key code -> our key name, for the special keys."""
    import glfw

    return {getattr(glfw, f"KEY_{name}"): value for name, value in SPECIAL.items() if hasattr(glfw, f"KEY_{name}")}


def install_callbacks(window, app) -> None:
    """Route glfw's mouse, scroll and key callbacks of ``window`` into ``app.handle``."""
    import glfw

    table = key_table()

    def on_key(_w, key, scancode, action, _mods):
        if action == glfw.REPEAT:
            return
        name = table.get(key) or (glfw.get_key_name(key, scancode) or "").lower()
        if name:
            app.handle(Key(name, action == glfw.PRESS))

    glfw.set_cursor_pos_callback(window, lambda _w, x, y: app.handle(MouseMove(float(x), float(y))))
    glfw.set_mouse_button_callback(
        window, lambda _w, b, action, _m: app.handle(MouseButton(BUTTONS.get(b, "other"), action == glfw.PRESS)))
    glfw.set_scroll_callback(window, lambda _w, _dx, dy: app.handle(Scroll(float(dy))))
    glfw.set_key_callback(window, on_key)
