"""The synchronous Python client of an Arboretum server (used by the GUI, scripts and tests).

    with Remote("tcp://127.0.0.1:5555") as r:
        sid = r.new_session("my tree").session
        r.add_example(sid, "scan-0001", np.eye(4))
        glb = r.export_mesh(sid, progress=print).data.tobytes()

One DEALER socket, used from one thread. Every call has a timeout; on a timeout the socket is closed
(linger 0) and a new one connects (the "lazy pirate" pattern), and the request is sent again with the
same id and the same client token (a random header key "client", one per ``Remote``): the server
keys replies and jobs by (token, id, type), so a retried edit is answered, never applied twice, a
retried job keeps running and answers the new socket, and two clients never share a reply. LONG requests stream ``Progress`` events; each event restarts the timeout, and a progress
callback that returns False cancels the job. Failures raise ``RemoteError`` with the server's code.
"""

from __future__ import annotations

import os
import secrets
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import zmq

from . import protocol as P
from .errors import ArboretumError, InputError, ProtocolError

R = TypeVar("R", bound=P.Reply)
ProgressCallback = Callable[[float, float, str], Any]


class RemoteError(ArboretumError):
    """The server answered with an error, or did not answer in time (code 'timeout')."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


class Remote:
    """A connection to an Arboretum server. For a ``serve --curve`` server, ``curve`` is a key folder from
    ``arboretum keys generate`` or one client's ``*.key_secret``, and ``curve_client`` names the client
    whose secret to use from the folder (see ``client_keys``)."""

    def __init__(self, endpoint: str = "tcp://127.0.0.1:5555", *, timeout: float = 10.0, retries: int = 2,
                 curve: str | os.PathLike | None = None, curve_client: str | None = None,
                 handshake: bool = True, zctx: zmq.Context | None = None) -> None:
        self.endpoint = endpoint
        self.timeout = timeout
        self.retries = retries
        if curve is None and curve_client is not None:

            raise InputError(f"curve_client={curve_client!r} needs curve=KEYDIR")
        self._curve = client_keys(curve, curve_client) if curve is not None else None
        self._zctx = zctx or zmq.Context.instance()
        self._next_id = secrets.randbits(40) << 20
        self.client = secrets.token_hex(16)
        """This client's token, sent with every request (and every retry)."""
        self._sock: zmq.Socket | None = None
        self.welcome: P.Welcome | None = None
        if handshake:
            self.welcome = self.call(P.Hello())

    # -- plumbing ------------------------------------------------------------------------------
    def _socket(self) -> zmq.Socket:
        s = self._sock
        if s is None:
            s = self._zctx.socket(zmq.DEALER)
            s.setsockopt(zmq.LINGER, 0)
            if self._curve is not None:
                s.curve_serverkey, s.curve_publickey, s.curve_secretkey = self._curve
            s.connect(self.endpoint)
            self._sock = s
        return s if self._sock is None else self._sock

    def _reset(self) -> None:
        if self._sock is not None:
            self._sock.close(0)
            self._sock = None

    def close(self) -> None:
        self._reset()

    def __enter__(self) -> Remote:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def call(self, req: P.Request, *, timeout: float | None = None, retries: int | None = None,
             progress: ProgressCallback | None = None) -> Any:
        """Send ``req`` and return its reply (of type ``req.REPLY``); ``RemoteError`` on an error reply."""
        self._next_id += 1
        rid = self._next_id
        frames = P.to_frames(req, rid, self.client)
        wait = self.timeout if timeout is None else timeout
        for _ in range((self.retries if retries is None else retries) + 1):
            self._socket().send_multipart(frames, copy=False)
            reply = self._await(rid, wait, progress)
            if reply is not None:
                if isinstance(reply, P.Error):
                    raise RemoteError(reply.code, reply.message)
                if not isinstance(reply, req.REPLY):
                    raise RemoteError("protocol", f"{req.TYPE}: expected {req.REPLY.TYPE}, got {reply.TYPE}")
                return reply
            self._reset()  # lazy pirate: a fresh socket, then the same request again
        raise RemoteError("timeout", f"{req.TYPE}: no answer from {self.endpoint} within {wait:g} s")

    def _await(self, rid: int, wait: float, progress: ProgressCallback | None) -> P.Msg | None:
        sock = self._socket()
        deadline = time.monotonic() + wait
        while (left := deadline - time.monotonic()) > 0:
            if not sock.poll(int(left * 1000) + 1, zmq.POLLIN):
                continue
            frames = sock.recv_multipart(copy=False)
            try:
                got, msg = P.parse([f.buffer for f in frames])
            except ProtocolError as exc:
                raise RemoteError(getattr(exc, "code", "protocol"), f"unreadable reply: {exc}") from None
            if got != rid:
                continue  # a late answer to an earlier, abandoned request
            if isinstance(msg, P.Progress):
                deadline = time.monotonic() + wait
                if progress is not None and progress(msg.done, msg.total, msg.message) is False:
                    sock.send_multipart(P.to_frames(P.Cancel(request=rid), rid + (1 << 62), self.client))
                continue
            return msg
        return None

    # -- operations ----------------------------------------------------------------------------
    def ping(self) -> float:
        """Round-trip time in seconds."""
        t = time.perf_counter()
        self.call(P.Ping())
        return time.perf_counter() - t

    def library_list(self, species: str = "", tags: Sequence[str] = ()) -> list[dict]:
        return list(self.call(P.LibraryList(species=species, tags=tuple(tags))).entries)

    def search(self, query: str, limit: int = 50) -> list[dict]:
        return list(self.call(P.LibrarySearch(query=query, limit=limit)).hits)

    def get_example(self, example_id: str):
        return self.call(P.LibraryGet(id=example_id)).example

    def delete_example_from_library(self, example_id: str) -> None:
        self.call(P.LibraryDelete(id=example_id))

    def import_scan(self, points: np.ndarray, *, labels: np.ndarray | None = None, name: str = "scan",
                    species: str = "unknown", options: dict | None = None,
                    progress: ProgressCallback | None = None, timeout: float = 120.0) -> P.LibraryImported:
        req = P.LibraryImport(points=points, labels=labels, name=name, species=species, options=options or {})
        return self.call(req, progress=progress, timeout=timeout)

    def new_session(self, name: str = "") -> P.SessionInfo:
        return self.call(P.SessionNew(name=name))

    def assembly(self, session: str) -> P.SessionAssembly:
        return self.call(P.SessionGet(session=session))

    def add_example(self, session: str, example_id: str, T_world_example: np.ndarray | None = None,
                    scale: float = 1.0, instance: str = "") -> P.Edit:
        T = np.eye(4) if T_world_example is None else T_world_example
        return self.call(P.AddExample(session=session, example_id=example_id, T_world_example=T, scale=scale,
                                      instance=instance))

    def transform_example(self, session: str, instance: str, T_world_example: np.ndarray, scale: float = 1.0) -> P.Edit:
        return self.call(P.TransformExample(session=session, instance=instance, T_world_example=T_world_example,
                                            scale=scale))

    def transform_lobe(self, session: str, instance: str, lobe: int, T_example_lobe: np.ndarray) -> P.Edit:
        return self.call(P.TransformLobe(session=session, instance=instance, lobe=lobe, T_example_lobe=T_example_lobe))

    def delete_placement(self, session: str, instance: str) -> P.Edit:
        return self.call(P.DeleteExample(session=session, instance=instance))

    def sketch(self, session: str, strokes: Sequence[np.ndarray], instance: str = "") -> P.Edit:
        pts, sizes = P.pack_strokes(strokes)
        return self.call(P.SketchExample(session=session, stroke_points=pts, stroke_sizes=sizes, instance=instance))

    def undo(self, session: str) -> P.Edit:
        return self.call(P.Undo(session=session))

    def redo(self, session: str) -> P.Edit:
        return self.call(P.Redo(session=session))

    def grow(self, session: str, seed: int = 0, options: dict | None = None,
             progress: ProgressCallback | None = None, timeout: float = 120.0) -> P.GrownTree:
        return self.call(P.Grow(session=session, seed=seed, options=options or {}), progress=progress, timeout=timeout)

    def export_mesh(self, session: str, format: str = "glb", seed: int = 0, lod: int = 0,
                    options: dict | None = None, progress: ProgressCallback | None = None,
                    timeout: float = 120.0) -> P.ExportFile:
        req = P.ExportMesh(session=session, format=format, seed=seed, lod=lod, options=options or {})
        return self.call(req, progress=progress, timeout=timeout)


CLIENT = "client"
"""The client key pair ``curve=DIR`` uses when ``DIR`` holds several (``arboretum keys generate``'s default)."""


def client_keys(curve: str | os.PathLike, name: str | None = None) -> tuple[bytes, bytes, bytes]:
    """(server public, client public, client secret), Z85, for ``Remote(curve=...)``.

    ``curve`` is a folder from ``arboretum keys generate`` (its ``NAME.key_secret`` when ``name`` is given,
    else ``client.key_secret``, else its only client secret) or the path of one ``*.key_secret``; either
    way ``server.key`` lies next to the secret. ``InputError`` naming the file for a missing, unreadable or
    malformed key, listing the secrets when several could be meant, and naming both files when the folder's
    ``clients/NAME.key`` (the key the server accepts for that secret) is not the secret's public half."""

    path = Path(curve)
    if path.is_file():
        if name is not None:
            raise InputError(f"{path}: a client name ({name!r}) picks a secret in a key folder; give the folder "
                             "or this file alone")
        if path.name == "server.key_secret":
            raise InputError(f"{path}: is the server's secret key; give a client's *.key_secret")
        folder, secret = path.parent, path
    elif path.is_dir():
        folder, secret = path, path / f"{_choose_client(path, name)}.key_secret"
    else:
        raise InputError(f"{path}: no such key folder or *.key_secret file (make keys with 'arboretum keys generate DIR')")
    if not (folder / "server.key").is_file():
        raise InputError(f"{folder}: needs server.key (the server's public key) next to {secret.name}")
    server_pub, _ = load_key(folder / "server.key")
    pub, sec = load_key(secret, secret=True)
    assert sec is not None  # load_key(secret=True) checked it
    _check_accepted(folder, secret, pub)
    return server_pub, pub, sec


def accepted_key(secret: Path) -> Path | None:
    """``clients/NAME.key`` beside the client secret ``NAME.key_secret``: the public key a server keeping
    this folder accepts it by. None when ``secret`` is no client secret (the server's, a hidden temporary)
    or there is no such file (a revoked client, a copy without the server's ``clients/``): nothing to check."""
    name = secret.name.removesuffix(".key_secret")
    public = secret.parent / "clients" / f"{name}.key"
    if name == secret.name or name == "server" or name.startswith(".") or not public.is_file():
        return None
    return public


def _check_accepted(folder: Path, secret: Path, pub: bytes) -> None:
    """``InputError`` naming both files when ``accepted_key(secret)`` is not the public half ``pub`` of
    the secret: the server would refuse it, seen as a timeout."""
    accepted = accepted_key(secret)
    if accepted is None or load_key(accepted)[0] == pub:
        return
    name = secret.name.removesuffix(".key_secret")
    raise InputError(f"{secret} and {accepted} are not one key pair (a 'keys generate --force' cut short?), so the "
                     f"server would refuse this secret, seen as a timeout; run 'arboretum keys generate {folder} "
                     f"--client {name} --force' and restart the server (or, if the server's clients/{name}.key is "
                     "newer than this copy, copy it here)")


def same_pair(secret: str | os.PathLike, public: str | os.PathLike) -> bool:
    """Whether the public-key file ``public`` holds the public half of the secret-key file ``secret``;
    ``InputError`` naming a file that cannot be read as its kind (see ``load_key``)."""
    return load_key(public)[0] == load_key(secret, secret=True)[0]


def _choose_client(folder: Path, name: str | None) -> str:
    """The client key pair to use from ``folder`` (see ``client_keys``)."""

    found = sorted(p.name[: -len(".key_secret")] for p in folder.glob("*.key_secret")
                   if p.name != "server.key_secret" and not p.name.startswith("."))
    listed = ", ".join(found) or "none"
    if name is not None:
        if name not in found:
            raise InputError(f"{folder}: no {name}.key_secret (client secrets here: {listed})")
        return name
    if CLIENT in found:
        return CLIENT
    if len(found) == 1:
        return found[0]
    if not found:
        raise InputError(f"{folder}: needs server.key and a client *.key_secret (arboretum keys generate)")
    raise InputError(f"{folder}: holds several client secrets ({listed}) and no {CLIENT}.key_secret; choose one by "
                     f"the path of its .key_secret (e.g. {folder / found[0]}.key_secret) or, in Python, "
                     f"curve_client={found[0]!r}")


def load_key(path: str | os.PathLike, *, secret: bool = False) -> tuple[bytes, bytes | None]:
    """(public, secret or None), Z85, from a CurveZMQ certificate file. ``InputError`` naming ``path`` when it
    cannot be read, holds no well-formed public key or, with ``secret``, no secret key matching it; without
    ``secret`` (a public-key file, the kind handed to others) when it holds a secret key too."""
    import zmq.auth


    path = Path(path)
    try:
        pub, sec = zmq.auth.load_certificate(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    except (ValueError, IndexError):
        empty = path.stat().st_size == 0
        raise InputError(f"{path}: {'is empty' if empty else 'holds no public-key line'}, not a CurveZMQ key "
                         "file") from None
    _check_z85(path, "public", pub)
    if not secret and sec is not None:  # never print the key itself
        raise InputError(f"{path}: is a public-key file (the kind given to others) but holds a secret-key line, "
                         "so that secret may have leaked; keep secrets only in *.key_secret files")
    if secret:
        if sec is None:
            raise InputError(f"{path}: holds no secret key")
        _check_z85(path, "secret", sec)
        if zmq.curve_public(sec) != pub:
            raise InputError(f"{path}: its secret key does not belong to its public key (edited or mixed files?)")
    return pub, sec


def _check_z85(path: Path, kind: str, key: bytes) -> None:
    """``InputError`` unless ``key`` is 40 Z85 characters encoding 32 bytes."""
    import struct

    from zmq.utils import z85


    ok = len(key) == 40 and all(c in z85.Z85CHARS for c in key)
    try:
        ok = ok and len(z85.decode(key)) == 32
    except (ValueError, struct.error):  # a group above 2**32 - 1
        ok = False
    if not ok:
        raise InputError(f"{path}: its {kind} key is not 40 Z85 characters (truncated or edited?)")
