"""``arboretum keys generate DIR``: CurveZMQ key pairs for a server and its clients.

Writes ``DIR/server.key`` (public, give it to clients), ``DIR/server.key_secret`` (keep it on the
server), ``DIR/client.key_secret`` (give it to a client) and ``DIR/clients/client.key`` (the public keys
the server accepts: one file per client). ``arboretum serve --curve DIR`` and
``Remote(..., curve=DIR)`` read them.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("keys", help="CurveZMQ keys for 'arboretum serve --curve'")
    sub = p.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    g = sub.add_parser("generate", help="write a server key pair and a client key pair into DIR")
    g.add_argument("dir", metavar="DIR", help="folder for the key files (created)")
    g.add_argument("--client", default="client", help="name of the client key pair (default: client)")
    g.add_argument("--force", action="store_true", help="overwrite existing key files")
    add_json_flag(g)
    g.set_defaults(func=run)


def generate(folder: str | os.PathLike, client: str = "client", force: bool = False) -> dict[str, str]:
    """Create the key files in ``folder``; returns their paths. ``InputError`` if they exist (unless ``force``)."""
    import zmq.auth

    from arboretum_library.errors import InputError

    root = Path(folder)
    if not client.replace("-", "").replace("_", "").isalnum():
        raise InputError(f"--client {client!r}: use letters, digits, '-' and '_'")
    targets = [root / "server.key_secret", root / f"{client}.key_secret"]
    if not force and any(t.exists() for t in targets):
        raise InputError(f"{root} already holds keys (use --force to overwrite)")
    (root / "clients").mkdir(parents=True, exist_ok=True)
    server_pub, server_sec = zmq.auth.create_certificates(root, "server")
    client_pub, client_sec = zmq.auth.create_certificates(root, client)
    accepted = root / "clients" / f"{client}.key"
    os.replace(client_pub, accepted)
    for secret in (server_sec, client_sec):
        os.chmod(secret, 0o600)
    return {"server_public": str(server_pub), "server_secret": str(server_sec),
            "client_secret": str(client_sec), "client_public": str(accepted)}


def run(args: argparse.Namespace) -> int:
    paths = generate(args.dir, args.client, args.force)
    emit(args, paths, "\n".join(f"{k}: {v}" for k, v in paths.items()))
    return 0
