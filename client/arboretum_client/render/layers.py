"""Textured layers drawn after the opaque scene: billboards (reference photos in the world, far to near)
and the 2D user-interface image over the whole frame."""

from __future__ import annotations

import moderngl
import numpy as np

from arboretum_client.scene import Billboard

from .programs import set_uniforms
from .textures import TextureCache, bind


def draw_billboards(ctx: moderngl.Context, prog: moderngl.Program, vao: moderngl.VertexArray,
                    textures: TextureCache, billboards: list[Billboard], eye: np.ndarray, frame: dict) -> int:
    """Each billboard, far to near from ``eye`` (3,): one textured strip (``vao`` of ``prog``, corners
    from gl_VertexID), alpha-blended, depth-tested and written. Returns the number of draw calls."""
    if not billboards:
        return 0
    eye = np.asarray(eye, np.float64)
    ctx.enable(moderngl.BLEND)
    ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
    for b in sorted(billboards, key=lambda b: -np.linalg.norm(b.center - eye)):
        right, up = b.axes(eye)
        set_uniforms(prog, **frame, u_center=b.center, u_right=right, u_up=up)
        bind(prog, "u_image", textures.get(b.image))
        vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
    ctx.disable(moderngl.BLEND)
    return len(billboards)


class UILayer:
    """The 2D UI: an RGBA image at the output size blended over every frame (a full-screen triangle)."""

    def __init__(self, ctx: moderngl.Context, prog: moderngl.Program) -> None:
        self.ctx, self.prog = ctx, prog
        self.vao = ctx.vertex_array(prog, [])
        self.texture: moderngl.Texture | None = None
        self.on = False

    def set_image(self, image: np.ndarray | None) -> None:
        """Show (H, W, 4) uint8 RGBA ``image`` (None hides the layer); the texture is re-made only
        when the size changes."""
        if image is None:
            self.on = False
            return
        h, w = image.shape[:2]
        if self.texture is None or self.texture.size != (w, h):
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture((w, h), 4)
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.write(np.ascontiguousarray(image, np.uint8).tobytes())
        self.on = True

    def draw(self) -> int:
        """Blend the image over the bound framebuffer (depth test off); returns the draw calls (0 or 1)."""
        if not (self.on and self.texture is not None):
            return 0
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        bind(self.prog, "u_ui", self.texture)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.disable(moderngl.BLEND)
        return 1

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
        self.vao.release()
