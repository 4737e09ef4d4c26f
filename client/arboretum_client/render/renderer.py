"""The renderer: a Scene and a Camera in, pixels (and an ID buffer for picking) out.

It always draws into its own framebuffer, so a window and EGL differ only by the context. Passes:
1. background gradient (no depth); 2. ground grid; 3. opaque batches (tubes, meshes, instanced meshes,
points, lines; textured meshes cut out texels below their alpha cutoff); 3b. billboards (textured,
alpha-blended, one call each); 4. translucent meshes, sorted far to near by centre, alpha-blended with
depth writes off, each drawn back faces first then front faces. Anti-aliasing is MSAA when the context
offers it, else 2x supersampling downscaled on read-back. Picking renders the same opaque and
translucent batches with integer-output programs into an R32I buffer (nearest surface wins, cut-out
texels discarded), on demand; billboards are not in it (not pickable). Textures (billboards' and
meshes') live in a ``textures.TextureCache``: uploaded once per image, kept across uploads.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from arboretum_client.camera import Camera
from arboretum_client.scene import Billboard, InstancedMesh, Mesh, PointSet, Polyline, Scene

from . import buffers
from .layers import UILayer, draw_billboards
from .programs import Programs, set_uniforms
from .textures import Sampling, TextureCache, bind

SKY = (0.95, 0.97, 1.0)
GROUND = (0.55, 0.5, 0.45)
BACKGROUND_TOP = (0.98, 0.98, 0.99)
BACKGROUND_BOTTOM = (0.80, 0.82, 0.85)


@dataclass
class FrameStats:
    """What the last ``render`` issued."""

    draw_calls: int = 0
    triangles: int = 0
    points: int = 0
    segments: int = 0

    def count(self, mode: int, primitives: int) -> None:
        """Add one draw call of ``primitives`` triangles, points or segments (by moderngl ``mode``)."""
        self.draw_calls += 1
        if mode == moderngl.TRIANGLES:
            self.triangles += primitives
        elif mode == moderngl.POINTS:
            self.points += primitives
        else:
            self.segments += primitives


class Renderer:
    """Owns the programs, framebuffers and the uploaded scene of one GL context."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], antialias: str = "auto",
                 anisotropy: float | None = None) -> None:
        """``antialias``: 'auto' (4x MSAA when the context has it, else 2x supersampling), 'msaa',
        'supersample' or 'none'. ``anisotropy``: of mesh textures, None for ``default_anisotropy``."""
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        mode = ("msaa" if ctx.max_samples >= 4 else "supersample") if antialias == "auto" else antialias
        if mode not in ("msaa", "supersample", "none") or (mode == "msaa" and ctx.max_samples < 4):
            raise ValueError(f"antialias {antialias!r} is not possible here (max samples {ctx.max_samples})")
        self.samples = 4 if mode == "msaa" else 0
        """MSAA samples of the draw target (0 = none)."""
        self.scale = 2 if mode == "supersample" else 1
        """Supersampling factor: the draw target is ``scale`` times the output size."""
        self.programs = Programs.build(ctx)
        self._background = ctx.vertex_array(self.programs.color["background"], [])
        self._make_framebuffers()
        self.batches: list[buffers.Batch] = []
        self.overlay: list[buffers.Batch] = []
        self.highlight: dict = {}
        self.ui = UILayer(ctx, self.programs.color["ui"])
        self.grid: buffers.Batch | None = None
        self.billboards: list[Billboard] = []
        self.textures = TextureCache(ctx, anisotropy)
        """Billboard and mesh textures, uploaded once per image and kept across uploads."""
        self._billboard_vao = ctx.vertex_array(self.programs.color["billboard"], [])
        self.stats = FrameStats()
        self._camera: Camera | None = None
        self._pick_valid = False

    def _make_framebuffers(self) -> None:
        ctx, (w, h), s = self.ctx, self.size, self.scale
        inner = (w * s, h * s)
        self._fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer(inner, 4, samples=self.samples)],
                                    depth_attachment=ctx.depth_renderbuffer(inner, samples=self.samples))
        self.framebuffer = (ctx.framebuffer(color_attachments=[ctx.renderbuffer(inner, 4)])
                            if self.samples else self._fbo)
        """The resolved colour image (``scale`` times the output size)."""
        self._id_fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((w, h), 1, dtype="i4")],
                                       depth_attachment=ctx.depth_renderbuffer((w, h)))

    def _release_framebuffers(self) -> None:
        for fbo in {self._fbo, self._id_fbo, self.framebuffer}:
            for att in [*fbo.color_attachments, fbo.depth_attachment]:
                if att is not None:
                    att.release()
            fbo.release()

    def resize(self, size: tuple[int, int]) -> None:
        """Draw at a new output size from now on (a resized window): the render targets are made
        again; the uploaded scene, textures and UI layer are kept (the next UI image sets its size)."""
        size = (int(size[0]), int(size[1]))
        if size == self.size:
            return
        if min(size) < 1:
            raise ValueError(f"renderer size must be positive, got {size}")
        (self.ctx.screen or self.ctx.detect_framebuffer(0)).use()
        self._release_framebuffers()
        self.size = size
        self._make_framebuffers()
        self._camera, self._pick_valid = None, False

    # -- scene ---------------------------------------------------------------------------------
    def upload(self, scene: Scene) -> None:
        """Replace the GPU copy of the scene (buffers are built here, not per frame)."""
        self.clear_scene()
        self.batches = self._build(scene)
        self.grid = buffers.grid_batch(self.ctx, self.programs, scene.grid) if scene.grid else None
        self.billboards = [it for it in scene.items if isinstance(it, Billboard)]
        self._sync_textures()
        self._pick_valid = False

    @property
    def texture_uploads(self) -> int:
        """Textures uploaded since this renderer was made (tests check the cache)."""
        return self.textures.uploads

    @property
    def _textures(self) -> dict:
        """The texture cache's entries (the name the billboard tests know)."""
        return self.textures.entries

    def _sync_textures(self) -> None:
        """Upload the textures of new billboard images; free those no billboard or batch uses."""
        used = [self.textures.get(b.image) for b in self.billboards]
        self.textures.keep_only(used + [b.texture for b in self.batches + self.overlay if b.texture])

    def upload_overlay(self, scene: Scene) -> None:
        """Replace the overlay: small, often-changing items (hands, strokes, gizmos) drawn with the
        scene but never picked and never forcing the scene's buffers to be rebuilt."""
        for b in self.overlay:
            b.release()
        self.overlay = self._build(scene)
        self._sync_textures()

    def _build(self, scene: Scene) -> list[buffers.Batch]:
        ctx, progs, out = self.ctx, self.programs, []
        lines = [it for it in scene.items if isinstance(it, Polyline)]
        tubes = [p for p in lines if p.style == "tube"]
        if tubes:
            out.append(buffers.tubes_batch(ctx, progs, tubes))
        for width in sorted({p.width_px for p in lines if p.style == "line"}):
            group = [p for p in lines if p.style == "line" and p.width_px == width]
            out.append(buffers.segments_batch(ctx, progs, *buffers.polyline_segments(group), width))
        for it in scene.items:
            if isinstance(it, Mesh) and len(it.faces):
                out.append(buffers.mesh_batch(ctx, progs, it, self._texture_of(it)))
            elif isinstance(it, InstancedMesh) and len(it.matrices) and len(it.mesh.faces):
                out.append(buffers.instanced_batch(ctx, progs, it, self._texture_of(it.mesh)))
            elif isinstance(it, PointSet) and len(it.points):
                out.append(buffers.points_batch(ctx, progs, it))
        return out

    def _texture_of(self, mesh: Mesh) -> moderngl.Texture | None:
        if mesh.texture is None:
            return None
        return self.textures.get(mesh.texture, Sampling(repeat=True, cutoff=mesh.alpha_cutoff, anisotropic=True))

    def set_highlight(self, ids: tuple[int | None, int | None], colors: tuple[tuple, tuple]) -> None:
        """Tint the items with pick ids ``ids`` (left hand, right hand; None = nothing) in ``colors``."""
        self.highlight = {"u_hl_ids": tuple(-1.0 if i is None else float(i) for i in ids),
                          "u_hl_color0": colors[0], "u_hl_color1": colors[1]}

    def set_ui_image(self, image: np.ndarray | None) -> None:
        """The 2D UI layer: an (H, W, 4) uint8 RGBA image at the output size drawn over every frame
        (None removes it). Upload only when it changes; drawing it is one call."""
        self.ui.set_image(image)

    def clear_scene(self) -> None:
        for b in self.batches + ([self.grid] if self.grid else []):
            b.release()
        self.batches, self.grid = [], None

    # -- frame ---------------------------------------------------------------------------------
    def _frame_uniforms(self, camera: Camera, scale: int) -> dict:
        w, h = self.size
        vp = camera.projection_matrix(w / h) @ camera.view_matrix()
        return {"u_view_proj": vp, "u_eye": camera.eye, "u_sky": SKY, "u_ground": GROUND,
                "u_viewport": (w * scale / 2, h * scale / 2), "u_top": BACKGROUND_TOP,
                "u_bottom": BACKGROUND_BOTTOM, "u_hl_ids": (-1.0, -1.0), "u_hl_color0": (0, 0, 1),
                "u_hl_color1": (1, 0, 0), **self.highlight}

    def _draw(self, batch: buffers.Batch, pick: bool, frame: dict, scale: int) -> None:
        prog = (self.programs.pick if pick else self.programs.color)[batch.program]
        px = {k: v * scale for k, v in batch.uniforms.items()}
        set_uniforms(prog, **frame, **px)
        if batch.texture is not None:
            bind(prog, "u_texture", batch.texture)
            set_uniforms(prog, u_alpha_cutoff=batch.alpha_cutoff)
        cull = batch.cull and not batch.translucent  # the translucent pass culls on its own
        if cull:
            self.ctx.enable(moderngl.CULL_FACE)
            self.ctx.cull_face = "back"
        (batch.vao_pick if pick else batch.vao).render(batch.mode, instances=batch.instances)
        if cull:
            self.ctx.disable(moderngl.CULL_FACE)
        self.stats.count(batch.mode, batch.primitives)

    def render(self, camera: Camera) -> FrameStats:
        """Draw a frame into ``framebuffer``: ``issue`` then ``resolve``."""
        self.issue(camera)
        self.resolve()
        return self.stats

    def issue(self, camera: Camera) -> FrameStats:
        """Issue every draw call of a frame into the (multisampled) target; does not wait for the GPU."""
        ctx, s = self.ctx, self.scale
        self.stats = FrameStats()
        frame = self._frame_uniforms(camera, s)
        self._fbo.use()
        self._fbo.depth_mask = True
        self._fbo.clear(*BACKGROUND_BOTTOM, 1.0, depth=1.0)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        set_uniforms(self.programs.color["background"], **frame)
        self._background.render(moderngl.TRIANGLES, vertices=3)
        self.stats.draw_calls += 1
        ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        for b in ([self.grid] if self.grid else []) + [b for b in self.batches + self.overlay if not b.translucent]:
            self._draw(b, False, frame, s)
        n = draw_billboards(ctx, self.programs.color["billboard"], self._billboard_vao, self.textures,
                            self.billboards, camera.eye, frame)
        self.stats.draw_calls += n
        self.stats.triangles += 2 * n
        self._translucent_pass(camera, frame)
        self.stats.draw_calls += self.ui.draw()
        self._camera, self._pick_valid = camera, False
        return self.stats

    def resolve(self) -> None:
        """Resolve the multisampled image into ``framebuffer`` (waits for the frame's rendering)."""
        if self.samples:
            self.ctx.copy_framebuffer(self.framebuffer, self._fbo)

    def _translucent_pass(self, camera: Camera, frame: dict) -> None:
        ctx, eye = self.ctx, camera.eye
        glass = sorted((b for b in self.batches + self.overlay if b.translucent), key=lambda b: -np.linalg.norm(b.centre - eye))
        if not glass:
            return
        ctx.enable(moderngl.BLEND | moderngl.CULL_FACE)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        self._fbo.depth_mask = False
        for b in glass:
            for side in ("front", "back")[b.cull:]:  # cull front = draw the far (back) faces first
                ctx.cull_face = side
                self._draw(b, False, frame, self.scale)
        self._fbo.depth_mask = True
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)

    def present(self, target: moderngl.Framebuffer | None = None) -> None:
        """Copy the resolved image into ``target``: a window's ``ctx.screen``, or (None) whatever
        framebuffer is bound now, e.g. an OpenXR swapchain image's. Sizes must match (no supersampling)."""
        dst = target if target is not None else self.ctx.detect_framebuffer()
        self.ctx.copy_framebuffer(dst, self.framebuffer)

    def read(self) -> np.ndarray:
        """The last frame as an (H, W, 4) uint8 RGBA image, top row first, at the output size."""
        ws, hs = self.size[0] * self.scale, self.size[1] * self.scale
        img = np.frombuffer(self.framebuffer.read(components=4), np.uint8).reshape(hs, ws, 4)[::-1]
        if self.scale > 1:
            s = self.scale
            img = img.reshape(self.size[1], s, self.size[0], s, 4).mean(axis=(1, 3)).round().astype(np.uint8)
        return np.ascontiguousarray(img)

    # -- picking -------------------------------------------------------------------------------
    def render_ids(self) -> np.ndarray:
        """The ID buffer (H, W) int32 of the last rendered camera, top row first; 0 = nothing."""
        if self._camera is None:
            raise RuntimeError("render a frame before picking")
        if not self._pick_valid:
            self._render_pick_pass(self._camera)
        w, h = self.size
        return np.frombuffer(self._id_fbo.read(components=1, dtype="i4"), np.int32).reshape(h, w)[::-1].copy()

    def _render_pick_pass(self, camera: Camera) -> None:
        ctx = self.ctx
        frame = self._frame_uniforms(camera, 1)
        self._id_fbo.use()
        self._id_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        saved = self.stats
        self.stats = FrameStats()
        for b in self.batches:
            self._draw(b, True, frame, 1)
        self.stats, self._pick_valid = saved, True

    def pick(self, x: int, y: int) -> int | None:
        """The pick id of the object under output pixel (x right, y down), or None for nothing."""
        w, h = self.size
        if not (0 <= x < w and 0 <= y < h):
            return None
        if self._camera is None:
            raise RuntimeError("render a frame before picking")
        if not self._pick_valid:
            self._render_pick_pass(self._camera)
        raw = self._id_fbo.read(viewport=(int(x), h - 1 - int(y), 1, 1), components=1, dtype="i4")
        value = int(np.frombuffer(raw, np.int32)[0])
        return value if value > 0 else None

    def release(self) -> None:
        """Free every GL object of this renderer and bind the default framebuffer again (binding a
        deleted framebuffer later would be a GL error)."""
        self.clear_scene()
        self.billboards = []
        self.textures.release()
        self._billboard_vao.release()
        for b in self.overlay:
            b.release()
        self.overlay = []
        self.ui.release()
        (self.ctx.screen or self.ctx.detect_framebuffer(0)).use()
        self._release_framebuffers()
        self._background.release()
        self.programs.release()
