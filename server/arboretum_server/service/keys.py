"""``arboretum keys generate DIR [--client NAME]``: CurveZMQ key pairs for a server and its clients.

The first run writes ``DIR/server.key`` (public, give it to clients), ``DIR/server.key_secret`` (keep it
on the server), ``DIR/NAME.key_secret`` (give it to the client NAME, default ``client``) and
``DIR/clients/NAME.key`` (the public keys the server accepts: one file per client). A later run with a
new ``--client`` adds that client's pair and keeps the server's, so every client given keys before
stays accepted. ``--force`` replaces an existing client's pair (never the server's: a new server key
needs a new folder). ``arboretum serve --curve DIR`` and ``Remote(..., curve=DIR)`` read them.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit

SERVER = "server"
"""Base name of the server's key files (``server.key``, ``server.key_secret``): no client may use it."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("keys", help="CurveZMQ keys for 'arboretum serve --curve'")
    sub = p.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    g = sub.add_parser("generate", help="write a server key pair (once) and a client key pair into DIR")
    g.add_argument("dir", metavar="DIR", help="folder for the key files (created)")
    g.add_argument("--client", default="client",
                   help="name of the client key pair (default: client); a new name adds a client and keeps "
                        "the server key")
    g.add_argument("--force", action="store_true", help="replace this client's existing key pair")
    add_json_flag(g)
    g.set_defaults(func=run)


def check_client(client: str) -> None:
    """InputError for a client name that is not a plain file name or is the server's."""
    from arboretum_library.errors import InputError

    if not client or not client.replace("-", "").replace("_", "").isalnum() or not client.isascii():
        raise InputError(f"--client {client!r}: use letters, digits, '-' and '_'")
    if client.lower() == SERVER:
        raise InputError(f"--client {client!r}: '{SERVER}' names the server's own key files; choose another name")


def generate(folder: str | os.PathLike, client: str = "client", force: bool = False) -> dict[str, str]:
    """Create the client's key files in ``folder`` (and the server's when missing); returns their paths
    and ``server_key`` ('created' or 'kept'). ``InputError`` if the client's keys exist (unless ``force``)."""
    import zmq.auth

    from arboretum_library.errors import InputError

    check_client(client)
    root = Path(folder)
    if root.exists() and not root.is_dir():
        raise InputError(f"DIR {root}: is a file, not a folder")
    server_pub, server_sec = root / f"{SERVER}.key", root / f"{SERVER}.key_secret"
    client_sec, accepted = root / f"{client}.key_secret", root / "clients" / f"{client}.key"
    if server_pub.exists() != server_sec.exists():
        raise InputError(f"{root} holds only one of {server_pub.name} and {server_sec.name}; "
                         "restore the other or use a new folder")
    if not force and (client_sec.exists() or accepted.exists()):
        raise InputError(f"{root} already holds keys for the client {client!r} "
                         "(use --force to replace them, or --client NAME to add another client)")
    (root / "clients").mkdir(parents=True, exist_ok=True)
    kept = server_sec.exists()
    if not kept:
        server_pub, server_sec = map(Path, zmq.auth.create_certificates(root, SERVER))
        os.chmod(server_sec, 0o600)
    client_pub, client_sec = map(Path, zmq.auth.create_certificates(root, client))
    os.chmod(client_sec, 0o600)
    os.replace(client_pub, accepted)
    return {"server_public": str(server_pub), "server_secret": str(server_sec), "server_key": "kept" if kept else "created",
            "client_secret": str(client_sec), "client_public": str(accepted)}


def run(args: argparse.Namespace) -> int:
    paths = generate(args.dir, args.client, args.force)
    emit(args, paths, "\n".join(f"{k}: {v}" for k, v in paths.items()))
    return 0
