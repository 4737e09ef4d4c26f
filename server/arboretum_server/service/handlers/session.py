"""Session operations: new, list, get, save, load, close, the assembled HBL, undo and redo."""

from __future__ import annotations

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly
from arboretum_library.errors import InputError
from arboretum_server.assembly.state import History
from arboretum_server.assembly.world import assembly_to_hbl, resolver
from arboretum_server.service.context import Context
from arboretum_server.service.sessions import Session


def info(s: Session) -> P.SessionInfo:
    h = s.history
    return P.SessionInfo(session=s.id, name=h.name, revision=h.revision, placements=len(h.assembly.placements))


def edit_reply(s: Session, label: str = "", instance: str = "", merged=(), kinds=()) -> P.Edit:
    h = s.history
    return P.Edit(revision=h.revision, label=label or h.label, instance=instance, merged=merged, kinds=kinds,
                  can_undo=h.can_undo, can_redo=h.can_redo)


def new(ctx: Context, req: P.SessionNew) -> P.SessionInfo:
    return info(ctx.sessions.new(req.name))


def list_sessions(ctx: Context, req: P.SessionList) -> P.SessionInfos:
    return P.SessionInfos(sessions=tuple(dict(vars(info(s))) for s in ctx.sessions.all()))


def get(ctx: Context, req: P.SessionGet | P.SessionSave) -> P.SessionAssembly:
    s = ctx.sessions.get(req.session)
    h = s.history
    return P.SessionAssembly(assembly=h.assembly, revision=h.revision, can_undo=h.can_undo, can_redo=h.can_redo)


def load(ctx: Context, req: P.SessionLoad) -> P.SessionInfo:
    history = History().apply("load session", _checked(ctx, req.assembly))
    return info(ctx.sessions.new(req.name, history))


def _checked(ctx: Context, a: Assembly) -> Assembly:
    """``a`` if every placement names a sketch or a library example (``StoreError`` otherwise) and every
    lobe edit an existing lobe (``InputError`` naming the field). That the merge links form a forest and
    sketches lie within bounds is checked when the Assembly is built (``Assembly.__post_init__``): a
    request breaking it is refused as it is decoded, a ``protocol`` error naming ``Assembly.merges`` or
    ``Assembly.sketches``."""
    source = resolver(a, ctx.example)
    for i, p in enumerate(a.placements):
        n = len(source(p.example_id).structure.lobes)
        for j, lt in enumerate(p.lobe_transforms):
            if lt.lobe >= n:
                raise InputError(f"session.load: Assembly.placements[{i}].lobe_transforms[{j}].lobe: {lt.lobe} "
                                 f"does not exist ({p.example_id!r} has {n} lobes)")
    return a


def close(ctx: Context, req: P.SessionClose) -> P.Ack:
    ctx.sessions.close(req.session)
    return P.Ack(detail=f"closed {req.session}")


def hbl(ctx: Context, req: P.SessionHBL) -> P.SessionHBLReply:
    a = ctx.sessions.get(req.session).history.assembly
    return P.SessionHBLReply(hbl=assembly_to_hbl(a, ctx.example))


def undo(ctx: Context, req: P.Undo) -> P.Edit:
    s = ctx.sessions.get(req.session)
    s.commit(s.history.undo(), "undo")
    return edit_reply(s, "undo: " + s.history.steps[s.history.index + 1].label)


def redo(ctx: Context, req: P.Redo) -> P.Edit:
    s = ctx.sessions.get(req.session)
    s.commit(s.history.redo(), "redo")
    return edit_reply(s, "redo: " + s.history.label)


HANDLERS = {
    P.SessionNew: new, P.SessionList: list_sessions, P.SessionGet: get, P.SessionSave: get,
    P.SessionLoad: load, P.SessionClose: close, P.SessionHBL: hbl, P.Undo: undo, P.Redo: redo,
}
