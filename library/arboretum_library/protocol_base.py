"""The machinery under ``protocol``: message base classes, field specs, checks, registry, wire codec.

``arg`` and ``array`` declare fields, ``message`` registers a class under its wire type, ``Msg`` checks
every field when a message is built, ``to_frames``/``parse`` convert between messages and wire frames
and ``describe`` writes the reference page from the registry. The messages themselves live in
``protocol`` (one module that both ends import); ``REGISTRY`` is filled when it is imported.
"""

# No ``from __future__ import annotations`` here: the base classes' ClassVar annotations stay real
# objects, so ``typing.get_type_hints(message_class, vars(protocol))`` resolves them in any namespace.
import dataclasses
import functools
import math
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, dataclass, field
from typing import Any, ClassVar

import numpy as np

from .assembly import Assembly
from .codec import flatten, unflatten
from .errors import ArboretumError, ProtocolError, ValidationError
from .model import HBL, Example
from .wire import DEFAULT_LIMITS, PROTOCOL_VERSION, Limits, Message, decode, encode

REGISTRY: dict[str, type["Msg"]] = {}
"""Wire type name -> message class."""
RECORDS = (HBL, Example, Assembly)
MAX_STRING = 1 << 16


def arg(default: Any = MISSING, doc: str = "") -> Any:
    """A scalar or record field with a docstring (``default`` MISSING: required)."""
    if isinstance(default, dict):
        return field(default_factory=dict, metadata={"doc": doc})
    return field(default=default, metadata={"doc": doc})


def array(dtype: str, shape: tuple, doc: str, default: None = MISSING) -> Any:  # type: ignore[assignment]
    """An array field: canonical ``dtype`` ("<f8"), ``shape`` pattern (None = any size); ``default=None``
    makes it optional."""
    return field(default=default, metadata={"dtype": dtype, "shape": shape, "doc": doc})


@dataclass(frozen=True, kw_only=True)
class Msg:
    """Base of every message. Fields are checked against their annotations when built."""

    TYPE: ClassVar[str] = ""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = _check(type(self), f, getattr(self, f.name))
            object.__setattr__(self, f.name, value)


@dataclass(frozen=True, kw_only=True)
class Reply(Msg):
    """A final answer to one request."""


@dataclass(frozen=True, kw_only=True)
class Request(Msg):
    """A request; the server answers with ``REPLY`` (or ``Error``)."""

    REPLY: ClassVar[type[Reply]] = Reply
    LONG: ClassVar[bool] = False
    """True: runs as a job in a worker process, sends ``Progress`` events, can be cancelled."""


@typing.dataclass_transform(kw_only_default=True, frozen_default=True, field_specifiers=(arg, array, field))
def message(type_name: str, reply: type[Reply] | None = None, long: bool = False):
    """Class decorator: make a frozen keyword-only dataclass and register it as ``type_name``."""

    def wrap(cls):
        cls = dataclass(frozen=True, kw_only=True)(cls)
        if type_name in REGISTRY:
            raise ValueError(f"message type {type_name!r} registered twice")
        cls.TYPE = type_name
        if reply is not None:
            cls.REPLY = reply
        cls.LONG = long
        REGISTRY[type_name] = cls
        return cls

    return wrap


# -- checking ------------------------------------------------------------------------------------
@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """Resolved field annotations of ``cls`` (each class's names resolve in its own module)."""
    return typing.get_type_hints(cls)


def _check(cls: type, f: dataclasses.Field, value: Any) -> Any:
    where = f"{cls.TYPE or cls.__name__}.{f.name}"
    if "dtype" in f.metadata:
        if value is None and _required(f):
            raise ProtocolError(f"{where}: array is required")
        return _check_array(where, f.metadata, value)
    tp = _hints(cls)[f.name]
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        if value is None:
            return None
        tp = next(a for a in typing.get_args(tp) if a is not type(None))
    return _check_value(where, tp, value)


def _check_value(where: str, tp: Any, value: Any) -> Any:
    if tp in RECORDS:
        if not isinstance(value, tp):
            raise ProtocolError(f"{where}: expected a {tp.__name__} record")
        return value
    if tp is bool:
        if not isinstance(value, bool | np.bool_):
            raise ProtocolError(f"{where}: expected true or false, got {type(value).__name__}")
        return bool(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or abs(int(value)) >= 1 << 63:
            raise ProtocolError(f"{where}: expected an integer, got {type(value).__name__}")
        return int(value)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
            raise ProtocolError(f"{where}: expected a number, got {type(value).__name__}")
        if not math.isfinite(float(value)):
            raise ProtocolError(f"{where}: must be finite")
        return float(value)
    if tp is str:
        if not isinstance(value, str) or len(value) > MAX_STRING:
            raise ProtocolError(f"{where}: expected a string of at most {MAX_STRING} characters")
        return value
    if typing.get_origin(tp) is tuple:
        if not isinstance(value, list | tuple):
            raise ProtocolError(f"{where}: expected a list")
        elem = typing.get_args(tp)[0]
        return tuple(_check_value(f"{where}[{i}]", elem, v) for i, v in enumerate(value))
    if typing.get_origin(tp) is dict or tp is dict:
        if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
            raise ProtocolError(f"{where}: expected a map with string keys")
        return dict(value)
    raise TypeError(f"{where}: unsupported field type {tp!r}")  # a bug in this module, not input


def _check_array(where: str, meta: Mapping[str, Any], value: Any) -> np.ndarray | None:
    if value is None:
        return None
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        raise ProtocolError(f"{where}: not an array") from None
    want = np.dtype(meta["dtype"])
    if arr.dtype.kind not in _KINDS[want.kind]:
        raise ProtocolError(f"{where}: dtype {arr.dtype.str} does not fit {want.str}")
    shape = meta["shape"]
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        raise ProtocolError(f"{where}: expected shape {_pattern(shape)}, got {tuple(arr.shape)}")
    out = arr.astype(want, copy=False)
    if want.kind == "f" and out.size and not np.isfinite(out).all():
        raise ProtocolError(f"{where}: holds NaN or infinite values")
    return out


_KINDS = {"f": "fiu", "i": "iu", "u": "u", "b": "b"}
"""Array kinds accepted for a canonical dtype kind (values are converted to the canonical dtype)."""


def _pattern(shape: tuple) -> str:
    """A shape pattern for people: (None, 3) -> "(N, 3)"."""
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"


# -- encoding ------------------------------------------------------------------------------------
def to_frames(msg: Msg, request_id: int, client: str = "") -> list[bytes | memoryview]:
    """The wire frames of ``msg`` answering or making request ``request_id``; ``client`` is the
    sender's token (optional header key "client", see ``wire``)."""
    body: dict[str, Any] = {}
    arrays: dict[str, np.ndarray] = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        if v is None:
            continue
        if isinstance(v, np.ndarray):
            arrays[f.name] = v
        elif isinstance(v, RECORDS):
            meta, recs = flatten(v)
            body[f.name] = meta
            arrays.update({f"{f.name}/{k}": a for k, a in recs.items()})
        else:
            body[f.name] = list(v) if isinstance(v, tuple) else v
    return encode(Message(msg.TYPE, request_id, body, arrays, client))


def from_message(m: Message) -> Msg:
    """The typed message of a decoded wire ``Message``; ``ProtocolError`` if it does not fit."""
    cls = REGISTRY.get(m.type)
    if cls is None:
        raise UnknownType(f"unknown message type {m.type[:80]!r}")
    hints = _hints(cls)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if "dtype" in f.metadata:
            if f.name in m.arrays:
                kwargs[f.name] = m.arrays[f.name]
        elif tp in RECORDS:
            if f.name in m.body:
                prefix = f.name + "/"
                recs = {k[len(prefix):]: a for k, a in m.arrays.items() if k.startswith(prefix)}
                try:
                    kwargs[f.name] = unflatten(tp, m.body[f.name], recs)
                except (ValidationError, TypeError, ValueError, KeyError, AttributeError) as exc:
                    raise ProtocolError(f"{m.type}.{f.name}: not a valid {tp.__name__}: {exc}") from None
        elif f.name in m.body:
            kwargs[f.name] = m.body[f.name]
    missing = [f.name for f in dataclasses.fields(cls) if f.name not in kwargs and _required(f)]
    extra = undeclared(cls, m) if issubclass(cls, Request) else ""
    if missing or extra:
        said = [f"missing field(s) {', '.join(missing)}"] if missing else []
        raise ProtocolError(f"{m.type}: " + "; ".join(said + ([extra] if extra else [])))
    return cls(**kwargs)


MAX_NAMED = 8
"""Names an undeclared-field error lists at most (a hostile request may send thousands)."""


def undeclared(cls: type, m: Message) -> str:
    """What of ``m``'s body and arrays a request of type ``cls`` does not declare, said with what it
    takes; "" when nothing. A body key that is no field (``specie``), an array frame that is no array
    field (``point``), or a record array (``FIELD/PATH``) without its record's ``FIELD`` in the body
    would be dropped without a word: the request would run with the default instead (a client's
    misspelt field). Header keys stay ignored (``wire``: the envelope takes optional keys)."""
    fields = dataclasses.fields(cls)
    hints = _hints(cls)
    takes_arrays = [f.name for f in fields if "dtype" in f.metadata]
    takes_body = [f.name for f in fields if "dtype" not in f.metadata]
    records = {f.name for f in fields if hints[f.name] in RECORDS and f.name in m.body}
    body = [k for k in m.body if k not in takes_body]
    arrays = [k for k in m.arrays if k not in takes_arrays and k.split("/", 1)[0] not in records]
    if not body and not arrays:
        return ""
    said = ([f"undeclared body field(s) {_names(body)}"] if body else []) + (
        [f"undeclared array(s) {_names(arrays)}"] if arrays else [])
    return (f"{'; '.join(said)} (a misspelt field?); {m.type} takes body fields {', '.join(takes_body) or 'none'} "
            f"and arrays {', '.join(takes_arrays) or 'none'}")


def _names(names: list[str]) -> str:
    """Up to ``MAX_NAMED`` of ``names``, quoted and cut to 40 characters each, then how many in all."""
    shown = ", ".join(repr(n[:40] + ("..." if len(n) > 40 else "")) for n in names[:MAX_NAMED])
    return shown + (f", ... ({len(names)} in all)" if len(names) > MAX_NAMED else "")


def _required(f: dataclasses.Field) -> bool:
    return f.default is MISSING and f.default_factory is MISSING


def parse(frames: Sequence[bytes | memoryview], limits: Limits = DEFAULT_LIMITS) -> tuple[int, Msg]:
    """(request id, typed message) of wire ``frames``; ``ProtocolError`` for anything malformed."""
    m = decode(frames, limits)
    return m.id, from_message(m)


def parse_request(frames: Sequence[bytes | memoryview], limits: Limits = DEFAULT_LIMITS) -> tuple[int, str, Msg]:
    """(request id, client token or "", typed message) of wire ``frames``; ``ProtocolError`` as ``parse``."""
    m = decode(frames, limits)
    return m.id, m.client, from_message(m)


class UnknownType(ProtocolError):
    """A message type this side does not know."""

    code = "unknown_type"


def error_code(exc: BaseException) -> str:
    """The wire error code of an exception (``internal`` for anything that is not a user error)."""
    return getattr(exc, "code", "error") if isinstance(exc, ArboretumError) else "internal"


# -- the reference page ------------------------------------------------------------------------
def _type_text(cls: type, f: dataclasses.Field) -> str:
    if "dtype" in f.metadata:
        return f"array `{f.metadata['dtype']}` {_pattern(f.metadata['shape'])}"
    tp = _hints(cls)[f.name]
    return str(tp.__name__) if tp in RECORDS else str(tp).replace("typing.", "").replace("NoneType", "None")


def describe() -> str:
    """The protocol reference (docs/protocol.md) as markdown, generated from the message classes."""
    lines = [
        "# Arboretum wire protocol", "",
        "Generated by `python -m arboretum_library.protocol > docs/protocol.md`; a test keeps it current.", "",
        f"Protocol version **{PROTOCOL_VERSION}**. Transport: ZeroMQ; the server binds a ROUTER socket, clients",
        "connect DEALER sockets. Frame 0 is a msgpack map `{v, id, type, body, arrays}`; each array field",
        "follows as its own raw frame, described in `arrays` by `[name, dtype, shape]` (little-endian dtypes",
        f"from `{', '.join(sorted(_allowed()))}`). Records (HBL, Example, Assembly) travel as",
        "`codec.flatten` metadata in the body plus one frame per record array, named `FIELD/PATH`.", "",
        "A request gets exactly one reply with its `id`: the reply type named below, or `error` with a",
        "`code` and a `message`. LONG requests run as jobs in worker processes; before the reply they send",
        "`progress` events with the same `id`, and `cancel` stops them (they then reply `error`/`cancelled`).",
        "Clients send `hello` first: a version mismatch is an `error` with code `version` naming both versions.", "",
        "Optional header key `client`: a random token of at most 64 characters, the same for every retry",
        "of the client (`Remote` makes one per instance). The server keys its reply cache and running jobs",
        "by (`client`, `id`, `type`), so a request resent with the same `id` on a new socket gets the",
        "original's progress and reply and is never run twice; clients without the key share one",
        "origin (as before tokens): they should use random 63-bit ids, or two of them get each other's replies.",
        "Replies of requests that change nothing (`ping`, `hello`, `cancel`, `library.list`, `library.search`,",
        "`library.get`, `session.list`, `session.get`, `session.hbl`, `refine.points`, `assembly.recognize`)",
        "are not kept: a retry runs again. A retry",
        "whose reply was dropped from the cache is answered `error`/`duplicate`, never run again. Peers",
        "ignore header keys they do not know, so this needs no new version. REQ sockets work too: the",
        "server strips their empty delimiter frame and puts it back on the reply.", "",
        "A request's body fields and arrays are its type's fields below, nothing else: a body key or an",
        "array frame the type does not declare (a misspelt `label`, an array under a record field that is",
        "not in the body) is answered `error`/`protocol` naming it and what the type takes, never dropped.",
        "Replies and events are read leniently: a client ignores body fields and arrays it does not know.", "",
    ]
    for name, cls in sorted(REGISTRY.items()):
        kind = "request" if issubclass(cls, Request) else "reply" if issubclass(cls, Reply) else "event"
        lines += [f"## `{name}` ({kind}, `{cls.__name__}`)", ""]
        doc = (cls.__doc__ or "").strip()
        if doc and not doc.startswith(cls.__name__ + "("):
            lines += [" ".join(doc.split()), ""]
        if issubclass(cls, Request):
            lines += [f"Reply: `{cls.REPLY.TYPE}`" + ("; LONG (progress events, cancellable)" if cls.LONG else ""), ""]
        fs = dataclasses.fields(cls)
        if fs:
            lines += ["| field | type | default | meaning |", "|---|---|---|---|"]
            for f in fs:
                default = "required" if _required(f) else "{}" if f.default is MISSING else repr(f.default)
                lines.append(f"| `{f.name}` | {_type_text(cls, f)} | {default} | {f.metadata.get('doc', '')} |")
            lines.append("")
    return "\n".join(lines)


def _allowed() -> frozenset[str]:
    from .wire import DTYPES

    return DTYPES
