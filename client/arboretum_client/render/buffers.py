"""GPU batches: scene items turned into vertex/index/instance buffers and vertex arrays.

Layouts (float32 unless said):
- lit: ``in_pos 3f, in_normal 3f, in_color 4f, in_id 1i`` per vertex, int32 index buffer.
- textured: ``in_pos 3f, in_normal 3f, in_uv 2f, in_color 4f, in_id 1i`` per vertex.
- instanced: ``in_pos 3f, in_normal 3f`` (textured: ``+ in_uv 2f``) per vertex; ``in_model 16f,
  in_icolor 3f, in_id 1i`` per instance (``/i``); the 4x4 matrices are stored column-major as GLSL
  reads them.
- points: ``in_pos 3f, in_color 3f, in_id 1i``; lines: ``in_pos 3f, in_color 4f, in_id 1i`` in
  vertex pairs (one pair per segment).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import moderngl
import numpy as np

from arboretum_client.scene import Grid, InstancedMesh, Mesh, PointSet, Polyline

from .meshes import tube_mesh, vertex_normals
from .programs import Programs


@dataclass
class Batch:
    """One draw call's worth of GPU data, with a vertex array for the colour and the pick program."""

    program: str
    """Key of ``Programs.color`` / ``Programs.pick``."""
    mode: int
    """moderngl primitive (TRIANGLES, POINTS, LINES)."""
    vao: moderngl.VertexArray
    vao_pick: moderngl.VertexArray
    primitives: int
    """Triangles (or points, or segments) drawn by one call, all instances included."""
    instances: int = 1
    translucent: bool = False
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """(3,) world centre, used to depth-sort translucent batches."""
    uniforms: dict = field(default_factory=dict)
    """Extra uniforms for this batch (point size, line width)."""
    buffers: list = field(default_factory=list)
    texture: moderngl.Texture | None = None
    """Bound to unit 0 for textured programs; owned by the renderer's ``TextureCache``, not the batch."""
    alpha_cutoff: float = 0.0
    """Texels with alpha below this are discarded (textured programs)."""
    cull: bool = False
    """Cull back faces (a mesh that is not double-sided)."""

    def release(self) -> None:
        for obj in [self.vao, self.vao_pick, *self.buffers]:
            obj.release()


def _interleave(*columns: np.ndarray) -> bytes:
    """Pack (N, k) columns (float32 or int32) side by side into one byte string."""
    n = len(columns[0])
    parts = [np.ascontiguousarray(c).reshape(n, -1).view(np.uint8).reshape(n, -1) for c in columns]
    return np.ascontiguousarray(np.concatenate(parts, axis=1)).tobytes()


def _vaos(ctx, progs: Programs, name: str, content: list, ibo=None):
    """A vertex array for the colour program and one for the pick program (unused inputs skipped)."""
    return tuple(ctx.vertex_array(p[name], content, index_buffer=ibo, index_element_size=4, skip_errors=True)
                 for p in (progs.color, progs.pick))


def lit_batch(ctx, progs: Programs, vertices, normals, colors, ids, faces, translucent=False) -> Batch:
    """A triangle batch from vertices (V, 3), normals (V, 3), colors (V, 4), ids (V,), faces (F, 3)."""
    vbo = ctx.buffer(_interleave(np.asarray(vertices, np.float32), np.asarray(normals, np.float32),
                                 np.asarray(colors, np.float32), np.asarray(ids, np.int32)))
    ibo = ctx.buffer(np.ascontiguousarray(faces, dtype=np.int32).tobytes())
    content = [(vbo, "3f 3f 4f 1i", "in_pos", "in_normal", "in_color", "in_id")]
    vao, vao_pick = _vaos(ctx, progs, "lit", content, ibo)
    centre = np.asarray(vertices, np.float64).mean(axis=0) if len(vertices) else np.zeros(3)
    return Batch("lit", moderngl.TRIANGLES, vao, vao_pick, len(faces), 1, translucent, centre, {}, [vbo, ibo])


def tubes_batch(ctx, progs: Programs, lines: list[Polyline], sides: int = 8) -> Batch:
    """All tube polylines merged into one batch (one draw call), colour and id per vertex."""
    v, n, f, owner = tube_mesh([(p.points, p.radii) for p in lines], sides)
    colors = np.stack([p.color for p in lines])[owner]
    ids = np.array([p.pick_id for p in lines], np.int32)[owner]
    return lit_batch(ctx, progs, v, n, colors, ids, f)


def mesh_batch(ctx, progs: Programs, mesh: Mesh, texture: moderngl.Texture | None = None) -> Batch:
    """One mesh, smooth-shaded with its normals (area-weighted vertex normals when it has none);
    ``texture`` is the GPU copy of ``mesh.texture`` (None draws it untextured)."""
    n = mesh.normals if mesh.normals is not None else vertex_normals(mesh.vertices, mesh.faces)
    colors = np.broadcast_to(mesh.color, (len(mesh.vertices), 4))
    ids = np.full(len(mesh.vertices), mesh.pick_id, np.int32)
    if texture is None or mesh.uv is None:
        batch = lit_batch(ctx, progs, mesh.vertices, n, colors, ids, mesh.faces, mesh.translucent)
    else:
        vbo = ctx.buffer(_interleave(mesh.vertices, np.asarray(n, np.float32), mesh.uv, colors, ids))
        ibo = ctx.buffer(np.ascontiguousarray(mesh.faces, dtype=np.int32).tobytes())
        content = [(vbo, "3f 3f 2f 4f 1i", "in_pos", "in_normal", "in_uv", "in_color", "in_id")]
        vao, vao_pick = _vaos(ctx, progs, "textured", content, ibo)
        centre = mesh.vertices.astype(np.float64).mean(axis=0) if len(mesh.vertices) else np.zeros(3)
        batch = Batch("textured", moderngl.TRIANGLES, vao, vao_pick, len(mesh.faces), 1, mesh.translucent, centre,
                      {}, [vbo, ibo], texture, mesh.alpha_cutoff)
    batch.cull = not mesh.double_sided
    return batch


def instanced_batch(ctx, progs: Programs, item: InstancedMesh, texture: moderngl.Texture | None = None) -> Batch:
    """One mesh with N instance matrices: a single instanced draw call (textured with ``texture``,
    the GPU copy of ``item.mesh.texture``, when given)."""
    m = item.mesh
    textured = texture is not None and m.uv is not None
    normals = m.normals if m.normals is not None else vertex_normals(m.vertices, m.faces)
    per_vertex = [m.vertices.astype(np.float32), np.asarray(normals, np.float32)] + ([m.uv] if textured else [])
    vbo = ctx.buffer(_interleave(*per_vertex))
    ibo = ctx.buffer(np.ascontiguousarray(m.faces, dtype=np.int32).tobytes())
    n = len(item.matrices)
    colors = item.colors if item.colors is not None else np.broadcast_to(m.color[:3], (n, 3))
    cols = np.ascontiguousarray(item.matrices.transpose(0, 2, 1)).reshape(n, 16)
    inst = ctx.buffer(_interleave(cols.astype(np.float32), np.asarray(colors, np.float32),
                                  np.full(n, m.pick_id, np.int32)))
    layout = ("3f 3f 2f", "in_pos", "in_normal", "in_uv") if textured else ("3f 3f", "in_pos", "in_normal")
    content = [(vbo, *layout), (inst, "16f 3f 1i/i", "in_model", "in_icolor", "in_id")]
    name = "textured_instanced" if textured else "instanced"
    vao, vao_pick = _vaos(ctx, progs, name, content, ibo)
    centre = item.matrices[:, :3, 3].mean(axis=0) if n else np.zeros(3)
    return Batch(name, moderngl.TRIANGLES, vao, vao_pick, len(m.faces) * n, n, False, centre, {},
                 [vbo, ibo, inst], texture if textured else None, m.alpha_cutoff, not m.double_sided)


def points_batch(ctx, progs: Programs, item: PointSet) -> Batch:
    """A point set drawn as round dots ``item.size_px`` output pixels wide."""
    n = len(item.points)
    vbo = ctx.buffer(_interleave(item.points, item.colors, np.full(n, item.pick_id, np.int32)))
    vao, vao_pick = _vaos(ctx, progs, "points", [(vbo, "3f 3f 1i", "in_pos", "in_color", "in_id")])
    return Batch("points", moderngl.POINTS, vao, vao_pick, n, 1, False, item.points.mean(axis=0) if n else np.zeros(3),
                 {"u_point_px": item.size_px}, [vbo])


def segments_batch(ctx, progs: Programs, starts, ends, colors, ids, width_px: float) -> Batch:
    """Screen-space lines ``width_px`` wide from segments starts (S, 3) -> ends (S, 3)."""
    s = len(starts)
    pos = np.stack([starts, ends], axis=1).reshape(-1, 3).astype(np.float32)
    col = np.repeat(np.asarray(colors, np.float32), 2, axis=0)
    vbo = ctx.buffer(_interleave(pos, col, np.repeat(np.asarray(ids, np.int32), 2)))
    vao, vao_pick = _vaos(ctx, progs, "lines", [(vbo, "3f 4f 1i", "in_pos", "in_color", "in_id")])
    centre = pos.mean(axis=0) if s else np.zeros(3)
    return Batch("lines", moderngl.LINES, vao, vao_pick, s, 1, False, centre, {"u_width_px": width_px}, [vbo])


def polyline_segments(lines: list[Polyline]):
    """Segments of 'line'-style polylines: starts (S, 3), ends (S, 3), colors (S, 4), ids (S,)."""
    starts = np.concatenate([p.points[:-1] for p in lines])
    ends = np.concatenate([p.points[1:] for p in lines])
    counts = [len(p.points) - 1 for p in lines]
    colors = np.repeat(np.stack([p.color for p in lines]), counts, axis=0)
    ids = np.repeat([p.pick_id for p in lines], counts)
    return starts, ends, colors, ids


def grid_batch(ctx, progs: Programs, g: Grid) -> Batch:
    """The ground grid: lines every ``g.spacing`` across a square of half side ``g.half_size``, 1 px wide."""
    n = int(np.floor(g.half_size / g.spacing))
    ticks = np.arange(-n, n + 1) * g.spacing
    cx, cy, e = g.center[0], g.center[1], n * g.spacing
    starts = np.concatenate([np.c_[cx + ticks, np.full_like(ticks, cy - e)], np.c_[np.full_like(ticks, cx - e), cy + ticks]])
    ends = np.concatenate([np.c_[cx + ticks, np.full_like(ticks, cy + e)], np.c_[np.full_like(ticks, cx + e), cy + ticks]])
    z = np.full((len(starts), 1), g.z)
    colors = np.broadcast_to(np.asarray(g.color, np.float32), (len(starts), 4))
    return segments_batch(ctx, progs, np.c_[starts, z], np.c_[ends, z], colors, np.zeros(len(starts), np.int32), 1.0)
