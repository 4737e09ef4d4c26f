"""Find and call the handler of a typed request; every failure becomes an ``Error`` reply.

Each module of ``handlers`` (listed in ``HANDLER_MODULES``) exports ``HANDLERS``: a dict from request
class to a function ``(ctx, request) -> Reply | Job``. A new concern plugs in as one more module. A module
that cannot be imported (an optional dependency missing) is logged and its operations reply 'unavailable'.
A module may list in ``WARM`` the heavy modules its inline handlers use; ``serve`` imports them in a
thread as soon as it listens, and calls a heavy module's ``warm()`` when it has one (its compiled loops
loaded from numba's cache, or compiled: 24 s for refinement's on a fresh install and 3.4 s from the
cache on session 24's machine, which runs session 23's code 2-4 times slower), so the first such
request does not stall every client behind an import or a compilation.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from typing import Any

from arboretum_library import protocol as P
from arboretum_library.errors import ArboretumError

from .context import Context
from .jobs import Job, call_target

log = logging.getLogger("arboretum.service")

HANDLER_MODULES = ("core", "library", "session", "assembly", "refine", "grow", "export", "modules")
Handler = Callable[[Context, Any], Any]


def load_handlers(modules: tuple[str, ...] = HANDLER_MODULES) -> dict[type, Handler]:
    """Request class -> handler, from every importable handler module."""
    table: dict[type, Handler] = {}
    for name in modules:
        try:
            mod = importlib.import_module(f"{__package__}.handlers.{name}")
        except ImportError as exc:
            log.warning("handlers.%s unavailable: %s", name, exc)
            continue
        for cls, fn in mod.HANDLERS.items():
            if cls in table:
                raise RuntimeError(f"{cls.TYPE} handled twice")
            table[cls] = fn
    return table


def warm_up(modules: tuple[str, ...] = HANDLER_MODULES) -> None:
    """Import what the handler modules list in ``WARM``, and run their ``warm()``."""
    for name in modules:
        try:
            mod = importlib.import_module(f"{__package__}.handlers.{name}")
            for heavy in getattr(mod, "WARM", ()):
                warm = getattr(importlib.import_module(heavy), "warm", None)
                if warm is not None:
                    warm()
        except ImportError as exc:
            log.warning("warm-up of handlers.%s: %s", name, exc)


def error_reply(exc: BaseException, where: str = "") -> P.Error:
    """The ``Error`` reply of an exception; anything but an ``ArboretumError`` is logged as a bug."""
    if isinstance(exc, ArboretumError):
        return P.Error(code=P.error_code(exc), message=str(exc)[:2000] or type(exc).__name__)
    log.error("internal error in %s", where or "handler", exc_info=exc)
    return P.Error(code="internal", message=f"internal error ({type(exc).__name__}) in {where or 'handler'}; see the server log")


class Dispatcher:
    """Calls handlers; turns exceptions into ``Error`` replies."""

    def __init__(self, ctx: Context, handlers: dict[type, Handler] | None = None) -> None:
        self.ctx = ctx
        self.handlers = load_handlers() if handlers is None else handlers
        self.ctx.operations = tuple(sorted(c.TYPE for c in self.handlers))

    def handle(self, req: P.Msg) -> P.Reply | Job:
        """The reply to ``req``, or the ``Job`` that will produce it."""
        fn = self.handlers.get(type(req))
        if fn is None:
            return P.Error(code="unavailable", message=f"this server does not handle {req.TYPE!r}")
        try:
            out = fn(self.ctx, req)
        except Exception as exc:
            return error_reply(exc, req.TYPE)
        if not isinstance(out, P.Reply | Job):
            return error_reply(TypeError(f"handler returned {type(out).__name__}"), req.TYPE)
        return out

    def finish(self, job: Job, result: Any, where: str) -> P.Reply:
        try:
            return job.finish(result)
        except Exception as exc:
            return error_reply(exc, where)

    def run(self, req: P.Msg, progress: Callable[[float, float, str], None] | None = None) -> P.Reply:
        """Handle ``req`` in this process, running any job inline (scripts, tests)."""
        out = self.handle(req)
        if isinstance(out, Job):
            try:
                result = call_target(out.target, out.kwargs, progress or (lambda *a: None))
            except Exception as exc:
                return error_reply(exc, req.TYPE)
            return self.finish(out, result, req.TYPE)
        return out
