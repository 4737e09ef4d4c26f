"""Assembly edits (VRTree 3.5): add, transform, transform lobe, delete, sketch; stroke recognition.

Each edit runs a pure function of ``assembly.ops`` on the session's current assembly and commits the
result (autosaved) before replying. These handlers run inline, in the server's loop, so strokes are
bounded (``checked_strokes``): a request too big to answer in well under a second is refused with a
``bad_input`` error naming the limit instead of stalling every other client.
"""

from __future__ import annotations

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.assembly import MAX_OFFSET
from arboretum_library.errors import InputError
from arboretum_server.assembly import ops
from arboretum_server.assembly.sketch import recognise
from arboretum_server.service.context import Context

from .session import edit_reply

WARM = ("arboretum_server.decompose.similarity", "arboretum_server.decompose.merge")
MAX_STROKES = 10_000
"""Strokes in one recognize or split-lobe request (a hand-drawn sketch has tens)."""
MAX_SKETCH_STROKES = 1_000
"""Strokes in one sketch (each becomes a branch or a lobe of the new example: 1,000 take ~0.4 s)."""
MAX_STROKE_POINTS = 1_000_000
"""Samples of all strokes in one request (a minute of drawing at 90 Hz is about 5,400)."""
MAX_SKETCH_LENGTH = 10_000.0
"""Metres: the strokes of one sketch together (branches are resampled every 5 cm: 200,000 vertices)."""


def checked_strokes(points: np.ndarray, sizes: np.ndarray, what: str, max_strokes: int = MAX_STROKES) -> list[np.ndarray]:
    """The strokes of ``points`` (P, 3) split by ``sizes`` (K,), each (S_k, 3); ``InputError`` naming
    the limit when there are too many strokes or samples, or a sample lies beyond ``MAX_OFFSET``."""
    if len(sizes) > max_strokes:
        raise InputError(f"{what}: {len(sizes)} strokes, at most {max_strokes} are taken in one request")
    if len(points) > MAX_STROKE_POINTS:
        raise InputError(f"{what}: {len(points)} stroke samples, at most {MAX_STROKE_POINTS} are taken in one request")
    if len(sizes) and (sizes.min() < 0 or sizes.max() > len(points)):
        raise InputError(f"{what}: stroke sizes must be 0..{len(points)} (the samples sent)")
    if len(points) and np.abs(points).max() > MAX_OFFSET:
        raise InputError(f"{what}: a stroke sample lies {np.abs(points).max():.3g} m out; at most {MAX_OFFSET:g} m is taken")
    return P.unpack_strokes(points, sizes)


def _sketch_length(strokes: list[np.ndarray]) -> float:
    return float(sum(np.linalg.norm(np.diff(s, axis=0), axis=1).sum() for s in strokes))


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
    strokes = checked_strokes(req.stroke_points, req.stroke_sizes, "sketch", MAX_SKETCH_STROKES)
    if (length := _sketch_length(strokes)) > MAX_SKETCH_LENGTH:
        raise InputError(f"sketch: the strokes are {length:.3g} m long together, at most {MAX_SKETCH_LENGTH:g} m is taken")
    return _commit(ctx, req.session, lambda a: ops.sketch(a, ctx.example, strokes, req.instance, ctx.recombine))


def recognize(ctx: Context, req: P.RecognizeStrokes) -> P.StrokeKinds:
    strokes = checked_strokes(req.stroke_points, req.stroke_sizes, "recognize")
    return P.StrokeKinds(kinds=tuple(recognise(s) for s in strokes))


HANDLERS = {
    P.AddExample: add, P.TransformExample: transform, P.TransformLobe: transform_lobe,
    P.DeleteExample: delete, P.SketchExample: sketch, P.RecognizeStrokes: recognize,
}
