"""``arboretum keys generate DIR [--client NAME]``: CurveZMQ key pairs for a server and its clients.

The first run writes ``DIR/server.key`` (public, give it to clients), ``DIR/server.key_secret`` (keep it
on the server), ``DIR/NAME.key_secret`` (give it to the client NAME, default ``client``) and
``DIR/clients/NAME.key`` (the public keys the server accepts: one file per client). A later run with a
new ``--client`` adds that client's pair and keeps the server's, so every client given keys before
stays accepted. ``--force`` replaces an existing client's pair (never the server's: a new server key
needs a new folder) and mends a pair whose two files disagree, which a run without it reports. Runs on
one folder at once take turns (a lock on the folder; a run that finds it taken says so on stderr and
gives up after ``--wait`` seconds, default ``LOCK_TIMEOUT_S``), so two new clients added together share
one server pair. A pair is written to ``.NAME.key_secret.new`` and ``clients/.NAME.key.new`` (synced to
disk), then renamed into place, secret first, with Ctrl-C held back: a run killed (SIGKILL, power cut)
after the secret's rename leaves the public half aside, and the next run on the folder renames it into
place under the lock before anything else (a leftover from before the first rename is deleted, the old
pair standing). ``arboretum serve --curve DIR`` (which refuses a ``server.key`` not matching
``server.key_secret`` or holding a secret, and a ``NAME.key_secret`` in DIR not matching
``clients/NAME.key``) and ``Remote(..., curve=DIR)`` read them.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit, tell

SERVER = "server"
"""Base name of the server's key files (``server.key``, ``server.key_secret``): no client may use it."""

LOCK_TIMEOUT_S = 30.0
"""How long a run waits for another run's lock on the key folder before giving up (an ``InputError``);
the default of ``--wait``."""

NEW = ".new"
"""Suffix of the files a pair is written to before its renames (``.NAME.key_secret.new``, ``.NAME.key.new``)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("keys", help="CurveZMQ keys for 'arboretum serve --curve'")
    sub = p.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    g = sub.add_parser("generate", help="write a server key pair (once) and a client key pair into DIR")
    g.add_argument("dir", metavar="DIR", help="folder for the key files (created)")
    g.add_argument("--client", default="client",
                   help="name of the client key pair (default: client); a new name adds a client and keeps "
                        "the server key")
    g.add_argument("--force", action="store_true",
                   help="replace this client's existing key pair (also mends a pair whose files disagree)")
    g.add_argument("--wait", type=float, default=None, metavar="SECONDS",
                   help=f"how long to wait for another run on DIR to finish (default {LOCK_TIMEOUT_S:g}; "
                        "0: do not wait; inf: as long as it takes)")
    add_json_flag(g)
    g.set_defaults(func=run)


def check_client(client: str) -> None:
    """InputError for a client name that is not a plain file name or is the server's."""
    from arboretum_library.errors import InputError

    if not client or not client.replace("-", "").replace("_", "").isalnum() or not client.isascii():
        raise InputError(f"--client {client!r}: use letters, digits, '-' and '_'")
    if client.lower() == SERVER:
        raise InputError(f"--client {client!r}: '{SERVER}' names the server's own key files; choose another name")


def check_wait(seconds: float) -> None:
    """InputError for a lock wait that is negative or not a number (``inf`` waits as long as it takes)."""
    from arboretum_library.errors import InputError

    if math.isnan(seconds) or seconds < 0:
        raise InputError(f"--wait {seconds:g}: give the seconds to wait for another run, 0 or more "
                         "(0: do not wait)")


def generate(folder: str | os.PathLike, client: str = "client", force: bool = False, *,
             timeout: float = LOCK_TIMEOUT_S, on_wait: Callable[[str], None] | None = None) -> dict[str, str]:
    """Create the client's key files in ``folder`` (and the server's when missing); returns their paths,
    ``server_key`` ('created' or 'kept') and, when a killed run's pair was finished first, ``recovered``
    (the public key files renamed into place). ``InputError`` if the client's keys exist (unless
    ``force``; a pair whose two files disagree is named as such), or when another run holds the folder's
    lock for ``timeout`` seconds (0: not waiting; ``on_wait`` is told once when the wait begins). Secret
    files are mode 0600 from their creation on, public ones 0644."""
    from arboretum_library.errors import InputError

    check_client(client)
    check_wait(timeout)
    root = Path(folder)
    if root.exists() and not root.is_dir():
        raise InputError(f"DIR {root}: is a file, not a folder")
    server_pub, server_sec = root / f"{SERVER}.key", root / f"{SERVER}.key_secret"
    client_sec, accepted = root / f"{client}.key_secret", root / "clients" / f"{client}.key"
    (root / "clients").mkdir(parents=True, exist_ok=True)
    with _locked(root, timeout, on_wait):  # another run on this folder waits: one server pair, never two
        recovered = _recover(root)
        if server_pub.exists() != server_sec.exists():
            raise InputError(f"{root} holds only one of {server_pub.name} and {server_sec.name}; "
                             "restore the other or use a new folder")
        finished = str(accepted) in recovered  # a killed run's new pair for this client, now whole: keep it
        if not force and not finished:
            _check_absent(root, client, client_sec, accepted)
        kept = server_sec.exists()
        if not kept:
            _write_pair(server_sec, server_pub)
        if force or not finished:
            _write_pair(client_sec, accepted)
    paths = {"server_public": str(server_pub), "server_secret": str(server_sec),
             "server_key": "kept" if kept else "created", "client_secret": str(client_sec),
             "client_public": str(accepted)}
    return paths | ({"recovered": ", ".join(recovered)} if recovered else {})


def _check_absent(root: Path, client: str, secret: Path, public: Path) -> None:
    """``InputError`` when ``client`` has key files in ``root`` already: naming both files when they are
    not one pair (a killed ``--force``, a file copied from elsewhere), so that ``--force`` mends it."""
    from arboretum_library.errors import InputError
    from arboretum_library.remote import same_pair

    if secret.exists() and public.exists():
        try:
            mismatch = not same_pair(secret, public)
        except InputError as exc:
            raise InputError(f"{exc}; rerun with --force to replace the client {client!r}'s pair") from None
        if mismatch:
            raise InputError(f"{secret} and {public} are not one key pair (a 'keys generate --force' cut short?), "
                             f"so the server refuses the client {client!r}; rerun with --force to replace both")
    if secret.exists() or public.exists():
        raise InputError(f"{root} already holds keys for the client {client!r} "
                         "(use --force to replace them, or --client NAME to add another client)")


SECRET_MODE, PUBLIC_MODE = 0o600, 0o644
"""File modes of ``*.key_secret`` (owner only, from the moment the file exists) and of public ``*.key``."""


@contextmanager
def _locked(root: Path, timeout: float, on_wait: Callable[[str], None] | None) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the folder ``root`` itself (no lock file is left behind): runs of
    ``generate`` on one folder, in threads or processes, check and write their keys one at a time. Waits
    at most ``timeout`` seconds for another run (``inf``: no limit); ``InputError`` naming the folder when
    that is over or when the folder cannot be locked at all (some network filesystems refuse ``flock`` on
    a folder)."""
    from arboretum_library.errors import InputError
    from arboretum_library.recovery import wait_for_lock

    waiting = f"waiting for another 'arboretum keys generate' on {root} ... (Ctrl-C to stop)"
    tell = (lambda: on_wait(waiting)) if on_wait is not None and timeout > 0 else None
    try:
        fd = os.open(root, os.O_RDONLY)
    except OSError as exc:
        raise InputError(f"DIR {root}: cannot be opened to lock it ({exc.strerror or exc})") from None
    try:
        try:
            got = wait_for_lock(fd, None if math.isinf(timeout) else timeout, tell)
        except OSError as exc:  # EBADF, ENOLCK, ... from filesystems without flock on folders
            raise InputError(f"DIR {root}: cannot be locked ({exc.strerror or exc}), so runs on it could not take "
                             "turns; use a folder on a local filesystem") from None
        if not got and timeout == 0:
            raise InputError(f"DIR {root}: another 'arboretum keys generate' is using it (--wait 0: not waiting); "
                             "try again when it is done")
        if not got:
            raise InputError(f"DIR {root}: another 'arboretum keys generate' held it for {timeout:g} s; "
                             "try again when it is done")
        yield
    finally:
        os.close(fd)  # releases the lock


def _recover(root: Path) -> list[str]:
    """Finish or undo the pair replacements a killed run left in ``root`` (call with its lock held): a
    leftover public half whose key is that of the secret in place is renamed into place (the kill came
    between the two renames); any other leftover (the kill came before them) is deleted, the old pair
    standing. Returns the public key files renamed into place."""
    from arboretum_library.codec import fsync_dir

    names = {p.name[1:-len(".key_secret" + NEW)] for p in root.glob(f".*.key_secret{NEW}")}
    names |= {p.name[1:-len(".key" + NEW)] for p in (root / "clients").glob(f".*.key{NEW}")}
    pairs = [(root / f"{SERVER}.key_secret", root / f"{SERVER}.key")]
    pairs += [(root / f"{n}.key_secret", root / "clients" / f"{n}.key") for n in sorted(names - {SERVER})]
    done = []
    for secret, public in pairs:
        if _rolls_forward(secret, _temp(public)):
            os.replace(_temp(public), public)
            fsync_dir(public.parent)
            done.append(str(public))
        _temp(secret).unlink(missing_ok=True)
        _temp(public).unlink(missing_ok=True)
    return done


def _rolls_forward(secret: Path, public_temp: Path) -> bool:
    """Whether ``public_temp`` holds the public key of ``secret`` (neither missing nor unreadable)."""
    from arboretum_library.errors import InputError
    from arboretum_library.remote import same_pair

    if not (secret.is_file() and public_temp.is_file()):
        return False
    try:
        return same_pair(secret, public_temp)
    except InputError:  # cut short while it was written: the renames had not begun
        return False


def _temp(path: Path) -> Path:
    """Where ``path`` is written before its rename: ``.NAME.new`` beside it (one name, so that the next run
    finds it)."""
    return path.with_name(f".{path.name}{NEW}")


def _write_pair(secret: Path, public: Path) -> None:
    """A new CurveZMQ key pair as the certificate files ``secret`` and ``public`` (the format
    ``zmq.auth.load_certificate`` reads). Both are written beside their places and synced (the public
    half first: it is whole before the secret exists), then renamed, secret first, the folder synced
    between, with Ctrl-C held back until the public one is in place: an interrupted run leaves the old
    pair or the new one, a killed one the new secret and its public half for ``_recover``."""
    import zmq

    from arboretum_library.atomic import interruptible
    from arboretum_library.codec import fsync_dir

    pub, sec = (k.decode("ascii") for k in zmq.curve_keypair())
    renaming = False
    try:
        _write_temp(_temp(public), "Public", f'    public-key = "{pub}"\n', PUBLIC_MODE)
        _write_temp(_temp(secret), "Secret", f'    public-key = "{pub}"\n    secret-key = "{sec}"\n', SECRET_MODE)
        fsync_dir(public.parent)  # the public half's name too is on disk before the secret's rename
        with interruptible():
            renaming = True
            os.replace(_temp(secret), secret)
            fsync_dir(secret.parent)  # on disk before the public half's rename can be
            os.replace(_temp(public), public)
            fsync_dir(public.parent)
    except BaseException:
        if not renaming or _temp(secret).exists():  # the old pair stands; else leave the public half to recover
            _temp(secret).unlink(missing_ok=True)
            _temp(public).unlink(missing_ok=True)
        raise


def _write_temp(path: Path, kind: str, keys: str, mode: int) -> None:
    """A certificate in the new file ``path`` (any older one there is replaced), opened with ``mode`` (so
    a secret is never readable by others, whatever the umask) and synced to disk."""
    text = (f"#   ZeroMQ CURVE {kind} Certificate, written by 'arboretum keys generate'\n"
            + ("#   Keep it private: it lets its holder in.\n" if kind == "Secret" else "")
            + f"\nmetadata\ncurve\n{keys}")
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "w", encoding="ascii") as fh:
        os.fchmod(fh.fileno(), mode)  # exact: the umask can only have narrowed it
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


def run(args: argparse.Namespace) -> int:
    wait = LOCK_TIMEOUT_S if args.wait is None else args.wait
    paths = generate(args.dir, args.client, args.force, timeout=wait, on_wait=tell)
    emit(args, paths, "\n".join(f"{k}: {v}" for k, v in paths.items()))
    return 0
