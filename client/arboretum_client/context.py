"""The one place that creates a GL context: EGL standalone when headless, a glfw window otherwise.

The renderer always draws into its own framebuffer, so both paths produce the same pixels; a window
only adds a final blit to its default framebuffer and ``swap``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import moderngl

from arboretum_library.errors import ArboretumError

GL_VERSION = 330
"""Every program is GLSL 3.30 core."""


class ContextError(ArboretumError):
    """No OpenGL 3.3 context could be created (missing EGL/Mesa, no display)."""

    code = "gl_context"


def create_headless_context() -> moderngl.Context:
    """A standalone OpenGL 3.3+ core context on EGL (Mesa llvmpipe when there is no GPU)."""
    try:
        return moderngl.create_standalone_context(backend="egl", require=GL_VERSION)  # pyright: ignore[reportArgumentType]
    except Exception as exc:  # moderngl/glcontext raise plain Exceptions with the loader's words
        raise ContextError(
            f"cannot create a headless OpenGL {GL_VERSION // 100}.{GL_VERSION % 100 // 10} context with EGL "
            f"({exc}); install Mesa's EGL and GL libraries (Debian: apt-get install libegl1 libgl1 "
            "libgles2 libegl-mesa0 libgl1-mesa-dri)"
        ) from None


@dataclass
class Window:
    """A glfw window with a current moderngl context. Close it with ``close()``."""

    handle: Any
    """The glfw window pointer."""
    ctx: moderngl.Context

    def swap(self) -> None:
        import glfw

        glfw.swap_buffers(self.handle)

    def close(self) -> None:
        import glfw

        self.ctx.release()
        glfw.destroy_window(self.handle)
        glfw.terminate()


def open_window(size: tuple[int, int], title: str = "Arboretum", visible: bool = True) -> Window:
    """Open a GL 3.3 core window on the X display named by ``DISPLAY`` and make its context current."""
    import glfw

    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise ContextError("cannot open a window: no display (DISPLAY is not set); render headless instead")
    glfw.ERROR_REPORTING = "raise"
    try:
        if not glfw.init():
            raise ContextError("glfw.init() failed: no usable display")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.VISIBLE, visible)
        handle = glfw.create_window(int(size[0]), int(size[1]), title, None, None)
        glfw.make_context_current(handle)
        ctx = moderngl.create_context(require=GL_VERSION)
    except glfw.GLFWError as exc:
        glfw.terminate()
        raise ContextError(f"cannot open a GL {GL_VERSION / 100:.1f} window: {exc}") from None
    return Window(handle, ctx)


def current_context() -> moderngl.Context:
    """A moderngl context over the GL context current on this thread (one made by someone else, e.g.
    pyopenxr's context provider for VR)."""
    try:
        return moderngl.create_context(require=GL_VERSION)
    except Exception as exc:
        raise ContextError(f"no usable OpenGL {GL_VERSION / 100:.1f} context is current ({exc})") from None
