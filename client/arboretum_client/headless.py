"""Render a Scene without a display: to an RGBA numpy image, or to a PNG file (pillow)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .camera import Camera, fit_camera
from .scene import Scene


class OffscreenRenderer:
    """An EGL context and a ``Renderer`` of one size; a context manager that releases both.

    >>> with OffscreenRenderer((640, 480)) as r:
    ...     image = r.render(scene, camera)   # (480, 640, 4) uint8
    """

    def __init__(self, size: tuple[int, int], antialias: str = "auto") -> None:
        from .context import create_headless_context
        from .render.renderer import Renderer

        self.ctx = create_headless_context()
        self.renderer = Renderer(self.ctx, size, antialias)
        self._scene: Scene | None = None

    def render(self, scene: Scene, camera: Camera | None = None, view: str = "iso") -> np.ndarray:
        """(H, W, 4) uint8 RGBA image of ``scene``; framed by ``fit_camera`` when camera is None."""
        with self.ctx:  # current for this block even if another context was made current since
            if scene is not self._scene:
                self.renderer.upload(scene)
                self._scene = scene
            w, h = self.renderer.size
            cam = camera or fit_camera(scene.bounds(), view, aspect=w / h)
            self.renderer.render(cam)
            return self.renderer.read()

    def pick(self, x: int, y: int) -> int | None:
        """Pick id under output pixel (x, y) of the last render, or None."""
        with self.ctx:
            return self.renderer.pick(x, y)

    def close(self) -> None:
        with self.ctx:
            self.renderer.release()
        self.ctx.release()

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_image(scene: Scene, size: tuple[int, int] = (1280, 720), camera: Camera | None = None,
                 view: str = "iso") -> np.ndarray:
    """One-shot: (H, W, 4) uint8 image of ``scene`` (creates and releases an EGL context)."""
    with OffscreenRenderer(size) as r:
        return r.render(scene, camera, view)


def save_png(image: np.ndarray, path: str | os.PathLike, compress_level: int = 6) -> Path:
    """Write an (H, W, 3|4) uint8 image as PNG atomically (temp file + rename); returns the path."""
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        Image.fromarray(np.ascontiguousarray(image)).save(tmp, format="PNG", compress_level=compress_level)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
