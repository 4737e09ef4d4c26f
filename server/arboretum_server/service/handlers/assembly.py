"""Assembly edits (VRTree 3.5): add, transform, transform lobe, delete, sketch; stroke recognition.

Each edit runs a pure function of ``assembly.ops`` on the session's current assembly and commits the
result (autosaved) before replying.
"""

from __future__ import annotations

from arboretum_library import protocol as P
from arboretum_server.assembly import ops
from arboretum_server.assembly.sketch import recognise
from arboretum_server.service.context import Context

from .session import edit_reply

WARM = ("arboretum_server.decompose.similarity", "arboretum_server.decompose.merge")


def _commit(ctx: Context, session_id: str, edit) -> P.Edit:
    s = ctx.sessions.get(session_id)
    assembly, out = edit(s.history.assembly)
    s.commit(s.history.apply(out.label, assembly))
    return edit_reply(s, out.label, out.instance, out.merged, out.kinds)


def add(ctx: Context, req: P.AddExample) -> P.Edit:
    return _commit(ctx, req.session, lambda a: ops.add_example(
        a, ctx.example, req.example_id, req.T_world_example, req.scale, req.instance, ctx.recombine))


def transform(ctx: Context, req: P.TransformExample) -> P.Edit:
    return _commit(ctx, req.session, lambda a: ops.transform_example(
        a, ctx.example, req.instance, req.T_world_example, req.scale, ctx.recombine))


def transform_lobe(ctx: Context, req: P.TransformLobe) -> P.Edit:
    return _commit(ctx, req.session, lambda a: ops.transform_lobe(a, ctx.example, req.instance, req.lobe, req.T_example_lobe))


def delete(ctx: Context, req: P.DeleteExample) -> P.Edit:
    return _commit(ctx, req.session, lambda a: ops.delete_example(a, req.instance))


def sketch(ctx: Context, req: P.SketchExample) -> P.Edit:
    strokes = P.unpack_strokes(req.stroke_points, req.stroke_sizes)
    return _commit(ctx, req.session, lambda a: ops.sketch(a, ctx.example, strokes, req.instance, ctx.recombine))


def recognize(ctx: Context, req: P.RecognizeStrokes) -> P.StrokeKinds:
    strokes = P.unpack_strokes(req.stroke_points, req.stroke_sizes)
    return P.StrokeKinds(kinds=tuple(recognise(s) for s in strokes))


HANDLERS = {
    P.AddExample: add, P.TransformExample: transform, P.TransformLobe: transform_lobe,
    P.DeleteExample: delete, P.SketchExample: sketch, P.RecognizeStrokes: recognize,
}
