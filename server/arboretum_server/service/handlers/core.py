"""Handshake, liveness and (in-process) cancellation."""

from __future__ import annotations

from arboretum_library import __version__
from arboretum_library import protocol as P
from arboretum_library.errors import ProtocolError
from arboretum_library.wire import PROTOCOL_VERSION
from arboretum_server.service.context import Context


class VersionMismatch(ProtocolError):
    code = "version"


def hello(ctx: Context, req: P.Hello) -> P.Welcome:
    """``Welcome``, or a 'version' error naming both protocol versions."""
    if req.protocol != PROTOCOL_VERSION:
        raise VersionMismatch(
            f"client speaks protocol {req.protocol} (Arboretum {req.client_version}), server speaks "
            f"{PROTOCOL_VERSION} (Arboretum {__version__}); update the older side"
        )
    return P.Welcome(protocol=PROTOCOL_VERSION, server_version=__version__, operations=ctx.operations)


def ping(ctx: Context, req: P.Ping) -> P.Pong:
    return P.Pong(ready=not ctx.warming)


def cancel(ctx: Context, req: P.Cancel) -> P.Ack:
    """Jobs run inline when there is no socket: nothing is ever left to cancel."""
    return P.Ack(detail=f"no running job {req.request}")


HANDLERS = {P.Hello: hello, P.Ping: ping, P.Cancel: cancel}
