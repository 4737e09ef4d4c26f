"""``arboretum keys generate DIR [--client NAME]``: CurveZMQ key pairs for a server and its clients.

The first run writes ``DIR/server.key`` (public, give it to clients), ``DIR/server.key_secret`` (keep it
on the server), ``DIR/NAME.key_secret`` (give it to the client NAME, default ``client``) and
``DIR/clients/NAME.key`` (the public keys the server accepts: one file per client). A later run with a
new ``--client`` adds that client's pair and keeps the server's, so every client given keys before
stays accepted. ``--force`` replaces an existing client's pair (never the server's: a new server key
needs a new folder). Runs on one folder at once take turns (a lock on the folder; a run that finds it
taken says so on stderr and gives up after ``LOCK_TIMEOUT_S``), so two new clients added together share
one server pair; each pair is written aside and renamed into place with Ctrl-C held back, so an
interrupted run leaves the old pair or the new one, never half of each. ``arboretum serve --curve DIR``
(which refuses a ``server.key`` not matching ``server.key_secret`` or holding a secret) and
``Remote(..., curve=DIR)`` read them.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit, tell

SERVER = "server"
"""Base name of the server's key files (``server.key``, ``server.key_secret``): no client may use it."""

LOCK_TIMEOUT_S = 30.0
"""How long a run waits for another run's lock on the key folder before giving up (an ``InputError``)."""


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


def generate(folder: str | os.PathLike, client: str = "client", force: bool = False, *,
             timeout: float = LOCK_TIMEOUT_S, on_wait: Callable[[str], None] | None = None) -> dict[str, str]:
    """Create the client's key files in ``folder`` (and the server's when missing); returns their paths
    and ``server_key`` ('created' or 'kept'). ``InputError`` if the client's keys exist (unless ``force``),
    or when another run holds the folder's lock for ``timeout`` seconds (``on_wait`` is told once when the
    wait begins). Secret files are mode 0600 from their creation on, public ones 0644."""
    from arboretum_library.errors import InputError

    check_client(client)
    root = Path(folder)
    if root.exists() and not root.is_dir():
        raise InputError(f"DIR {root}: is a file, not a folder")
    server_pub, server_sec = root / f"{SERVER}.key", root / f"{SERVER}.key_secret"
    client_sec, accepted = root / f"{client}.key_secret", root / "clients" / f"{client}.key"
    (root / "clients").mkdir(parents=True, exist_ok=True)
    with _locked(root, timeout, on_wait):  # another run on this folder waits: one server pair, never two
        if server_pub.exists() != server_sec.exists():
            raise InputError(f"{root} holds only one of {server_pub.name} and {server_sec.name}; "
                             "restore the other or use a new folder")
        if not force and (client_sec.exists() or accepted.exists()):
            raise InputError(f"{root} already holds keys for the client {client!r} "
                             "(use --force to replace them, or --client NAME to add another client)")
        kept = server_sec.exists()
        if not kept:
            _write_pair(server_sec, server_pub)
        _write_pair(client_sec, accepted)
    return {"server_public": str(server_pub), "server_secret": str(server_sec), "server_key": "kept" if kept else "created",
            "client_secret": str(client_sec), "client_public": str(accepted)}


SECRET_MODE, PUBLIC_MODE = 0o600, 0o644
"""File modes of ``*.key_secret`` (owner only, from the moment the file exists) and of public ``*.key``."""


@contextmanager
def _locked(root: Path, timeout: float, on_wait: Callable[[str], None] | None) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the folder ``root`` itself (no lock file is left behind): runs of
    ``generate`` on one folder, in threads or processes, check and write their keys one at a time. Waits
    at most ``timeout`` seconds for another run; ``InputError`` naming the folder when that is over or
    when the folder cannot be locked at all (some network filesystems refuse ``flock`` on a folder)."""
    from arboretum_library.errors import InputError
    from arboretum_library.recovery import wait_for_lock

    waiting = f"waiting for another 'arboretum keys generate' on {root} ... (Ctrl-C to stop)"
    tell = (lambda: on_wait(waiting)) if on_wait is not None else None
    try:
        fd = os.open(root, os.O_RDONLY)
    except OSError as exc:
        raise InputError(f"DIR {root}: cannot be opened to lock it ({exc.strerror or exc})") from None
    try:
        try:
            got = wait_for_lock(fd, timeout, tell)
        except OSError as exc:  # EBADF, ENOLCK, ... from filesystems without flock on folders
            raise InputError(f"DIR {root}: cannot be locked ({exc.strerror or exc}), so runs on it could not take "
                             "turns; use a folder on a local filesystem") from None
        if not got:
            raise InputError(f"DIR {root}: another 'arboretum keys generate' held it for {timeout:g} s; "
                             "try again when it is done")
        yield
    finally:
        os.close(fd)  # releases the lock


def _write_pair(secret: Path, public: Path) -> None:
    """A new CurveZMQ key pair as the certificate files ``secret`` and ``public`` (the format
    ``zmq.auth.load_certificate`` reads): both written to temporary files first, then renamed, secret
    first, with Ctrl-C held back until the public one is in place, so an interrupted run leaves the old
    pair or the new one (an existing pair is replaced only with ``--force``)."""
    import zmq

    from arboretum_library.atomic import interruptible

    pub, sec = (k.decode("ascii") for k in zmq.curve_keypair())
    temps: list[Path] = []
    try:
        temps.append(_write_temp(secret, "Secret", f'    public-key = "{pub}"\n    secret-key = "{sec}"\n',
                                 SECRET_MODE))
        temps.append(_write_temp(public, "Public", f'    public-key = "{pub}"\n', PUBLIC_MODE))
        with interruptible():
            os.replace(temps[0], secret)
            os.replace(temps[1], public)
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)


def _write_temp(path: Path, kind: str, keys: str, mode: int) -> Path:
    """A certificate in a new temporary file beside ``path``, opened with ``mode`` (so a secret is never
    readable by others, whatever the umask); its path. Nothing is left when writing fails."""
    import secrets

    text = (f"#   ZeroMQ CURVE {kind} Certificate, written by 'arboretum keys generate'\n"
            + ("#   Keep it private: it lets its holder in.\n" if kind == "Secret" else "")
            + f"\nmetadata\ncurve\n{keys}")
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    try:
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            os.fchmod(fh.fileno(), mode)  # exact: the umask can only have narrowed it
            fh.write(text)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def run(args: argparse.Namespace) -> int:
    paths = generate(args.dir, args.client, args.force, timeout=LOCK_TIMEOUT_S, on_wait=tell)
    emit(args, paths, "\n".join(f"{k}: {v}" for k, v in paths.items()))
    return 0
