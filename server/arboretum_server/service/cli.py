"""``arboretum serve``: the ZeroMQ server (see docs/server.md).

    arboretum serve [--bind tcp://127.0.0.1:5555] [--library LIB] [--state DIR]
                    [--curve KEYDIR | --insecure] [--workers 2] [--fsync]

Loopback only unless CurveZMQ keys (``arboretum keys generate KEYDIR``) or an explicit ``--insecure``
are given. Prints ``listening on ENDPOINT`` (``--bind tcp://127.0.0.1:0`` picks a free port).
"""

from __future__ import annotations

import argparse

DEFAULT_BIND = "tcp://127.0.0.1:5555"
LOOPBACK = ("tcp://127.0.0.1:", "tcp://localhost:", "tcp://[::1]:", "ipc://", "inproc://")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("serve", help="run the Arboretum server (ZeroMQ) for clients and scripts")
    p.add_argument("--bind", default=DEFAULT_BIND, help=f"endpoint to bind (default {DEFAULT_BIND})")
    p.add_argument("--library", default=None, metavar="LIB", help="example library (created if missing)")
    p.add_argument("--state", default="arboretum-state", metavar="DIR", help="session autosaves (default ./arboretum-state)")
    p.add_argument("--curve", default=None, metavar="KEYDIR", help="CurveZMQ keys from 'arboretum keys generate'")
    p.add_argument("--insecure", action="store_true", help="allow a non-loopback bind without encryption")
    p.add_argument("--workers", type=int, default=2, help="worker processes for long jobs (default 2)")
    p.add_argument("--fsync", action="store_true", help="fsync every autosave (survives power loss, slower)")
    p.add_argument("--verbose", action="store_true", help="log every malformed message")
    p.set_defaults(func=run)


def check_bind(bind: str, curve: str | None, insecure: bool) -> None:
    """``InputError`` unless ``bind`` is loopback or the user chose Curve keys or --insecure."""
    from arboretum_library.errors import InputError

    if not bind.startswith(("tcp://", "ipc://", "inproc://")):
        raise InputError(f"--bind {bind!r}: use tcp://HOST:PORT (or ipc://PATH)")
    if not bind.startswith(LOOPBACK) and curve is None and not insecure:
        raise InputError(f"--bind {bind}: binding beyond loopback needs --curve KEYDIR "
                         "(make keys with 'arboretum keys generate KEYDIR') or an explicit --insecure")


def curve_keys(folder: str):
    """(server public, server secret) and the authenticator accepting the keys in ``folder/clients/*.key``.

    Every key file is read here, before anything starts: one that cannot be read (a stray README.key, a
    truncated key), a public key file holding a secret too (a leak), a ``server.key`` that is not the
    public half of ``server.key_secret``, a client secret kept in ``folder`` that is not the pair of its
    ``clients/NAME.key`` or an empty ``clients/`` is an ``InputError`` naming it, never a server that
    silently refuses a client. Keys added later need a restart."""
    from pathlib import Path

    import zmq
    from zmq.auth.thread import ThreadAuthenticator

    from arboretum_library.errors import InputError
    from arboretum_library.remote import load_key

    root = Path(folder)
    secret = root / "server.key_secret"
    if not secret.is_file() or not (root / "clients").is_dir():
        raise InputError(f"--curve {folder}: no server.key_secret and clients/ (run 'arboretum keys generate {folder}')")
    pub, sec = load_key(secret, secret=True)
    check_server_public(root, pub)
    accepted = accepted_keys(root)
    check_client_pairs(root)
    auth = ThreadAuthenticator(zmq.Context.instance())
    auth.start()
    auth.configure_curve_callback(domain="*", credentials_provider=_Accepted(accepted))
    return (pub, sec), auth


def check_server_public(root, pub: bytes) -> None:
    """``InputError`` naming both files when ``root/server.key`` (the key the clients are given) is not the
    public half of ``root/server.key_secret`` (``pub``): every client would be refused, seen as a timeout;
    ``InputError`` naming it when it holds a secret key too (it is handed to clients: a leak). A folder
    without ``server.key`` passes (the server needs only its secret)."""
    from arboretum_library.errors import InputError
    from arboretum_library.remote import load_key

    public, secret = root / "server.key", root / "server.key_secret"
    if not public.exists():
        return
    try:
        given = load_key(public)[0]
    except InputError as exc:
        raise InputError(f"--curve {root}: {exc}") from None
    if given != pub:
        raise InputError(f"--curve {root}: {public} is not the public key of {secret}, so no client given it "
                         "could connect; restore the server.key made with that secret, or make a new key folder")


def accepted_keys(root) -> frozenset[bytes]:
    """The Z85 public keys of ``root/clients/*.key`` (dot files skipped); ``InputError`` naming the first
    file that is not a client's public key alone (a secret key in it too is refused), or when there is none."""
    from arboretum_library.errors import InputError
    from arboretum_library.remote import load_key

    files = sorted(p for p in (root / "clients").glob("*.key") if not p.name.startswith("."))
    if not files:
        raise InputError(f"--curve {root}: clients/ holds no client key (*.key), so no client could connect; "
                         f"add one with 'arboretum keys generate {root} --client NAME'")
    keys = set()
    for path in files:
        try:
            keys.add(load_key(path)[0])
        except InputError as exc:
            raise InputError(f"--curve {root}: {exc}; every clients/*.key must be a client's public key "
                             "(move other files out)") from None
    return frozenset(keys)


def check_client_pairs(root) -> None:
    """``InputError`` naming the files when a client secret kept in ``root`` (``NAME.key_secret``) is
    unreadable or not the pair of ``root/clients/NAME.key`` (a ``keys generate --force`` killed between
    its two renames): that client would be refused forever, seen as a timeout. Secrets not kept in
    ``root`` (given away, deleted) and revoked clients (no ``clients/NAME.key``) cannot be checked: they
    pass."""
    from arboretum_library.errors import InputError
    from arboretum_library.remote import accepted_key, same_pair

    bad: list[str] = []
    for secret in sorted(root.glob("*.key_secret")):
        public = accepted_key(secret)
        if public is None:
            continue
        try:
            if not same_pair(secret, public):
                bad.append(secret.name.removesuffix(".key_secret"))
        except InputError as exc:
            raise InputError(f"--curve {root}: {exc}, so it cannot be checked against {public}") from None
    if bad:
        files = "; ".join(f"{root / n}.key_secret is not the secret of {root / 'clients' / n}.key" for n in bad)
        mend = (f"run 'arboretum keys generate {root} --client {bad[0]} --force'" if len(bad) == 1 else
                f"run 'arboretum keys generate {root} --client NAME --force' for each of {', '.join(bad)}")
        raise InputError(f"--curve {root}: {files} (a 'keys generate --force' cut short?), so "
                         f"{'that client' if len(bad) == 1 else 'those clients'} would be refused, seen as a "
                         f"timeout; {mend} and hand out the new secret")


class _Accepted:
    """pyzmq's CURVE credentials provider: a client is let in when its public key was in ``clients/``."""

    def __init__(self, keys: frozenset[bytes]) -> None:
        self.keys = keys

    def callback(self, domain: str, key: bytes) -> bool:
        return key in self.keys


def run(args: argparse.Namespace) -> int:
    import logging
    import signal
    import sys
    import threading
    from pathlib import Path

    from arboretum_library.errors import InputError

    from .context import Context
    from .dispatch import Dispatcher, warm_up
    from .jobs import JobRunner
    from .sessions import Sessions
    from .socket import Server

    check_bind(args.bind, args.curve, args.insecure)
    if args.workers < 1:
        raise InputError("--workers must be at least 1")
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    keys, auth = curve_keys(args.curve) if args.curve else (None, None)
    state = Path(args.state)
    lock = _lock_state(state)
    ctx = Context(Sessions(state, fsync=args.fsync), Path(args.library) if args.library else None)
    server = Server(Dispatcher(ctx), args.bind, jobs=JobRunner(args.workers), curve_secret=keys)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: server.stop_event.set())
    print(f"listening on {server.endpoint}", flush=True)
    def warm() -> None:  # imports while serving; Ping answers ready=False until done
        warm_up()
        ctx.warming = False
        logging.getLogger(__name__).info("ready: handler modules imported")

    ctx.warming = True
    threading.Thread(target=warm, name="warm-up", daemon=True).start()
    try:
        server.serve_forever()
    finally:
        ctx.sessions.snapshot_all()
        ctx.close()
        if auth is not None:
            auth.stop()
        lock.close()
    return 0


def _lock_state(state):
    """Hold an exclusive lock on ``state/.lock`` so two servers never share one state folder."""
    import fcntl

    from arboretum_library.errors import InputError

    state.mkdir(parents=True, exist_ok=True)
    fh = open(state / ".lock", "a+b")
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.close()
        raise InputError(f"--state {state}: another server is using this folder") from None
    return fh
