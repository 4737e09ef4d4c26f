"""Every message between an Arboretum client and server, as typed records both ends import.

A message is a frozen dataclass registered under its wire ``TYPE``. Scalar fields (str, int, float,
bool, tuples of them, JSON maps) travel in the msgpack header's body; array fields travel as raw frames
(``wire``) and declare their dtype and shape, which are checked (and the dtype normalised) when the
message is built, on either end; record fields (``HBL``, ``Example``, ``Assembly``) travel through
``codec.flatten`` as body metadata plus one array frame per record array. A request names its reply
type; requests marked ``LONG`` run as jobs that send ``Progress`` events (same request id) before
their reply, and may be cancelled with ``Cancel``. Any failure comes back as an ``Error`` reply with a
``code`` and a message.

``python -m arboretum_library.protocol > docs/protocol.md`` writes the reference from this module.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, dataclass, field
from typing import Any, ClassVar

import numpy as np

from . import __version__
from .codec import flatten, unflatten
from .errors import ArboretumError, ProtocolError, ValidationError
from .model import HBL, Assembly, Example
from .wire import DEFAULT_LIMITS, PROTOCOL_VERSION, Limits, Message, decode, encode

REGISTRY: dict[str, type[Msg]] = {}
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
    return typing.get_type_hints(cls, vars(sys.modules[__name__]))


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
        pattern = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ProtocolError(f"{where}: expected shape {pattern}, got {tuple(arr.shape)}")
    out = arr.astype(want, copy=False)
    if want.kind == "f" and out.size and not np.isfinite(out).all():
        raise ProtocolError(f"{where}: holds NaN or infinite values")
    return out


_KINDS = {"f": "fiu", "i": "iu", "u": "u", "b": "b"}
"""Array kinds accepted for a canonical dtype kind (values are converted to the canonical dtype)."""


# -- encoding ------------------------------------------------------------------------------------
def to_frames(msg: Msg, request_id: int) -> list[bytes | memoryview]:
    """The wire frames of ``msg`` answering or making request ``request_id``."""
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
    return encode(Message(msg.TYPE, request_id, body, arrays))


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
    if missing:
        raise ProtocolError(f"{m.type}: missing field(s) {', '.join(missing)}")
    return cls(**kwargs)


def _required(f: dataclasses.Field) -> bool:
    return f.default is MISSING and f.default_factory is MISSING


def parse(frames: Sequence[bytes | memoryview], limits: Limits = DEFAULT_LIMITS) -> tuple[int, Msg]:
    """(request id, typed message) of wire ``frames``; ``ProtocolError`` for anything malformed."""
    m = decode(frames, limits)
    return m.id, from_message(m)


class UnknownType(ProtocolError):
    """A message type this side does not know."""

    code = "unknown_type"


def error_code(exc: BaseException) -> str:
    """The wire error code of an exception (``internal`` for anything that is not a user error)."""
    return getattr(exc, "code", "error") if isinstance(exc, ArboretumError) else "internal"


# -- strokes ---------------------------------------------------------------------------------------
def pack_strokes(strokes: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Strokes (each (S_k, 3)) as one (P, 3) float64 array and their sizes (K,) int64."""
    parts = [np.asarray(s, dtype=np.float64).reshape(-1, 3) for s in strokes]
    pts = np.concatenate(parts) if parts else np.zeros((0, 3))
    return pts, np.array([len(p) for p in parts], dtype=np.int64)


def unpack_strokes(points: np.ndarray, sizes: np.ndarray) -> list[np.ndarray]:
    """Inverse of ``pack_strokes``; ``ProtocolError`` when the sizes do not add up."""
    if (sizes < 0).any() or int(sizes.sum()) != len(points):
        raise ProtocolError(f"stroke sizes add up to {int(sizes.sum())}, but {len(points)} points came")
    return np.split(points, np.cumsum(sizes)[:-1]) if len(sizes) else []




# == the messages ====================================================================================
F8_44 = ("<f8", (4, 4))


# -- common ------------------------------------------------------------------------------------------
@message("error")
class Error(Reply):
    """A request failed. Codes: protocol, version, unknown_type, bad_input, invalid_record, store,
    not_found, busy, cancelled, internal."""

    code: str = arg(doc="machine-readable error code")
    message: str = arg(doc="one line for a person")


@message("progress")
class Progress(Msg):
    """An event sent while a LONG request runs (same request id as the request)."""

    done: float = arg(default=0.0, doc="work done so far")
    total: float = arg(default=0.0, doc="work in all (0: unknown)")
    message: str = arg(default="", doc="what is being done")


@message("ack")
class Ack(Reply):
    """A request that returns nothing succeeded."""

    detail: str = arg(default="", doc="what was done")


@message("welcome")
class Welcome(Reply):
    protocol: int = arg(doc="the server's protocol version")
    server_version: str = arg(doc="the server's Arboretum version")
    operations: tuple[str, ...] = arg(default=(), doc="request types this server handles")


@message("hello", Welcome)
class Hello(Request):
    """Version handshake: the server answers ``Welcome``, or ``Error`` (code 'version') naming both versions."""

    protocol: int = arg(default=PROTOCOL_VERSION, doc="the client's protocol version")
    client_version: str = arg(default=__version__, doc="the client's Arboretum version")


@message("pong")
class Pong(Reply):
    pass


@message("ping", Pong)
class Ping(Request):
    """Liveness check; answered inline, never queued behind jobs."""


@message("cancel", Ack)
class Cancel(Request):
    """Cancel the running LONG request ``request`` sent by this client; it then replies 'cancelled'."""

    request: int = arg(doc="request id of the job to cancel")


# -- library -----------------------------------------------------------------------------------------
@message("library.entries")
class LibraryEntries(Reply):
    entries: tuple[dict, ...] = arg(default=(), doc="catalog rows: id, species, source, tags, lobe_count, curvature, length, spread, height")


@message("library.list", LibraryEntries)
class LibraryList(Request):
    species: str = arg(default="", doc="only this species ('' = all)")
    tags: tuple[str, ...] = arg(default=(), doc="only examples with all these tags")


@message("library.hits")
class LibraryHits(Reply):
    hits: tuple[dict, ...] = arg(default=(), doc="id, score and matched terms, best first")


@message("library.search", LibraryHits)
class LibrarySearch(Request):
    """Keyword search (VRTree 3.4: dense, sparse, straight, curved, species, ids)."""

    query: str = arg(default="", doc="space-separated terms")
    limit: int = arg(default=50, doc="at most this many hits")


@message("library.example")
class LibraryExample(Reply):
    example: Example = arg(doc="the whole example")


@message("library.get", LibraryExample)
class LibraryGet(Request):
    id: str = arg(doc="example id")


@message("library.delete", Ack)
class LibraryDelete(Request):
    id: str = arg(doc="example id")


@message("library.imported")
class LibraryImported(Reply):
    ids: tuple[str, ...] = arg(default=(), doc="ids of the examples added to the library")
    stats: dict = arg(default={}, doc="decomposition counts")


@message("library.import", LibraryImported, long=True)
class LibraryImport(Request):
    """Decompose a scan (VRTree 3.4) and add one example per main branch to the library."""

    points: np.ndarray = array("<f8", (None, 3), "(N, 3) scan points, metres, Z up")
    labels: np.ndarray | None = array("|u1", (None,), "(N,) WOOD 0 / LEAF 1, optional", default=None)
    name: str = arg(default="scan", doc="source name; example ids are NAME-NNNN")
    species: str = arg(default="unknown", doc="species (picks N_m, N_l from VRTree Table 2)")
    options: dict = arg(default={}, doc="DecomposeOptions fields (n_main, n_lobes, points, height, seed, ...)")


# -- sessions ------------------------------------------------------------------------------------------
@message("session.info")
class SessionInfo(Reply):
    session: str = arg(doc="session id")
    name: str = arg(default="", doc="a name for people")
    revision: int = arg(default=0, doc="edits committed so far")
    placements: int = arg(default=0, doc="placed examples")


@message("session.new", SessionInfo)
class SessionNew(Request):
    name: str = arg(default="", doc="a name for people")


@message("session.infos")
class SessionInfos(Reply):
    sessions: tuple[dict, ...] = arg(default=(), doc="session, name, revision, placements of each session")


@message("session.list", SessionInfos)
class SessionList(Request):
    pass


@message("session.assembly")
class SessionAssembly(Reply):
    assembly: Assembly = arg(doc="the session's assembly")
    revision: int = arg(default=0, doc="edits committed so far")
    can_undo: bool = arg(default=False)
    can_redo: bool = arg(default=False)


@message("session.get", SessionAssembly)
class SessionGet(Request):
    session: str = arg(doc="session id")


@message("session.save", SessionAssembly)
class SessionSave(Request):
    """The session's assembly, to keep client-side (load it back with session.load)."""

    session: str = arg(doc="session id")


@message("session.load", SessionInfo)
class SessionLoad(Request):
    """A new session holding ``assembly``."""

    assembly: Assembly = arg(doc="an assembly saved earlier")
    name: str = arg(default="", doc="a name for people")


@message("session.close", Ack)
class SessionClose(Request):
    """Delete the session and its autosave."""

    session: str = arg(doc="session id")


@message("session.hbl_reply")
class SessionHBLReply(Reply):
    hbl: HBL = arg(doc="the assembled tree, merges applied, world frame")


@message("session.hbl", SessionHBLReply)
class SessionHBL(Request):
    """The assembled HBL (``assembly_to_hbl``): what growth and export consume."""

    session: str = arg(doc="session id")


@message("edit")
class Edit(Reply):
    """An edit was committed (and autosaved) before this reply was sent."""

    revision: int = arg(doc="edits committed so far in the session")
    label: str = arg(default="", doc="what the edit did")
    instance: str = arg(default="", doc="the placement it touched ('' if none)")
    merged: tuple[str, ...] = arg(default=(), doc="instances linked to it by recombination")
    kinds: tuple[str, ...] = arg(default=(), doc="recognised stroke kinds (sketch only): 'branch' or 'lobe'")
    can_undo: bool = arg(default=False)
    can_redo: bool = arg(default=False)


@message("session.undo", Edit)
class Undo(Request):
    session: str = arg(doc="session id")


@message("session.redo", Edit)
class Redo(Request):
    session: str = arg(doc="session id")


# -- assembly (VRTree 3.5) ------------------------------------------------------------------------------
@message("assembly.add", Edit)
class AddExample(Request):
    """Select example: place a library example (recombination runs afterwards)."""

    session: str = arg(doc="session id")
    example_id: str = arg(doc="library (or sketched) example id")
    T_world_example: np.ndarray = array(*F8_44, "(4, 4) rigid transform, example -> world")
    scale: float = arg(default=1.0, doc="uniform scale in the example frame")
    instance: str = arg(default="", doc="placement name ('' = generated)")


@message("assembly.transform", Edit)
class TransformExample(Request):
    """Transform example: move, turn and scale a placement (recombination runs afterwards)."""

    session: str = arg(doc="session id")
    instance: str = arg(doc="placement name")
    T_world_example: np.ndarray = array(*F8_44, "(4, 4) new rigid transform, example -> world")
    scale: float = arg(default=1.0, doc="new uniform scale")


@message("assembly.transform_lobe", Edit)
class TransformLobe(Request):
    """Transform lobe: a similarity about the lobe centre, in the example frame."""

    session: str = arg(doc="session id")
    instance: str = arg(doc="placement name")
    lobe: int = arg(doc="lobe index in the example")
    T_example_lobe: np.ndarray = array(*F8_44, "(4, 4) rotation, uniform scale, translation")


@message("assembly.delete", Edit)
class DeleteExample(Request):
    session: str = arg(doc="session id")
    instance: str = arg(doc="placement name")


@message("assembly.sketch", Edit)
class SketchExample(Request):
    """Sketch new example: strokes (world frame) recognised as branches or lobes become an example."""

    session: str = arg(doc="session id")
    stroke_points: np.ndarray = array("<f8", (None, 3), "(P, 3) all stroke samples, world frame")
    stroke_sizes: np.ndarray = array("<i8", (None,), "(K,) samples per stroke")
    instance: str = arg(default="", doc="placement name ('' = generated)")


@message("assembly.strokes")
class StrokeKinds(Reply):
    kinds: tuple[str, ...] = arg(default=(), doc="'branch' or 'lobe' for each stroke")


@message("assembly.recognize", StrokeKinds)
class RecognizeStrokes(Request):
    """Only recognise strokes (no edit)."""

    stroke_points: np.ndarray = array("<f8", (None, 3), "(P, 3) all stroke samples")
    stroke_sizes: np.ndarray = array("<i8", (None,), "(K,) samples per stroke")


# -- refinement (VRTree 3.4, Fig. 5) -----------------------------------------------------------------------
@message("refine.state")
class RefineState(Reply):
    hbl: HBL = arg(doc="the refined whole-tree HBL")
    revision: int = arg(default=0, doc="refinement edits so far")
    can_undo: bool = arg(default=False)
    can_redo: bool = arg(default=False)


@message("refine.open", RefineState, long=True)
class RefineOpen(Request):
    """Decompose a scan into the session's refinement draft."""

    session: str = arg(doc="session id")
    points: np.ndarray = array("<f8", (None, 3), "(N, 3) scan points, metres, Z up")
    labels: np.ndarray | None = array("|u1", (None,), "(N,) WOOD 0 / LEAF 1, optional", default=None)
    name: str = arg(default="scan", doc="source name")
    species: str = arg(default="unknown", doc="species")
    options: dict = arg(default={}, doc="DecomposeOptions fields")


@message("refine.cloud")
class RefineCloud(Reply):
    points: np.ndarray = array("<f4", (None, 3), "(N, 3) the draft's points, output frame")
    labels: np.ndarray = array("|u1", (None,), "(N,) WOOD 0 / LEAF 1")
    lobe_of: np.ndarray = array("<i4", (None,), "(N,) lobe of each point, -1 for none")


@message("refine.points", RefineCloud)
class RefinePoints(Request):
    """Send the draft's point cloud (to select points and draw split strokes on)."""

    session: str = arg(doc="session id")


@message("refine.remove_lobe", RefineState)
class RemoveLobe(Request):
    session: str = arg(doc="session id")
    lobe: int = arg(doc="lobe index")


@message("refine.insert_lobe", RefineState)
class InsertLobe(Request):
    session: str = arg(doc="session id")
    indices: np.ndarray = array("<i8", (None,), "(M,) selected point indices")


@message("refine.merge_lobes", RefineState)
class MergeLobes(Request):
    session: str = arg(doc="session id")
    lobes: tuple[int, ...] = arg(doc="two or more lobe indices")


@message("refine.split_lobe", RefineState)
class SplitLobe(Request):
    session: str = arg(doc="session id")
    lobe: int = arg(doc="lobe index")
    stroke_points: np.ndarray = array("<f8", (None, 3), "(P, 3) stroke samples, output frame")
    stroke_sizes: np.ndarray = array("<i8", (None,), "(K,) samples per stroke; one new lobe each")
    seed: int = arg(default=0, doc="k-means seed")


@message("refine.undo", RefineState)
class RefineUndo(Request):
    session: str = arg(doc="session id")


@message("refine.redo", RefineState)
class RefineRedo(Request):
    session: str = arg(doc="session id")


@message("refine.commit", LibraryImported)
class RefineCommit(Request):
    """Split the refined HBL into examples and add them to the library."""

    session: str = arg(doc="session id")


# -- growth and export -----------------------------------------------------------------------------------
@message("grow.tree")
class GrownTree(Reply):
    positions: np.ndarray = array("<f8", (None, 3), "(N, 3) node positions, metres, Z up")
    parents: np.ndarray = array("<i8", (None,), "(N,) parent node, -1 for roots")
    radii: np.ndarray = array("<f8", (None,), "(N,) radius of each node, metres")
    levels: np.ndarray = array("|u1", (None,), "(N,) MAIN 0, SECONDARY 1, TWIG 2")
    leaf_centres: np.ndarray = array("<f8", (None, 3), "(K, 3) leaf card centres")
    leaf_normals: np.ndarray = array("<f8", (None, 3), "(K, 3) leaf card normals")
    leaf_sizes: np.ndarray = array("<f8", (None,), "(K,) leaf card lengths, metres")


@message("grow", GrownTree, long=True)
class Grow(Request):
    """Grow twigs and leaves in the lobes of the assembled tree (VRTree Eq. 2)."""

    session: str = arg(doc="session id")
    seed: int = arg(default=0, doc="random seed (same seed, same tree)")
    options: dict = arg(default={}, doc="GrowOptions fields (density, leaf_density, step, alpha, beta, ...)")


@message("export.file")
class ExportFile(Reply):
    name: str = arg(doc="suggested file name")
    data: np.ndarray = array("|u1", (None,), "the file's bytes")
    stats: dict = arg(default={}, doc="counts (triangles, leaves, ...)")


@message("export.mesh", ExportFile, long=True)
class ExportMesh(Request):
    """Grow and mesh the assembled tree and return the file (glb, obj as zip, or ply)."""

    session: str = arg(doc="session id")
    format: str = arg(default="glb", doc="glb, obj or ply")
    seed: int = arg(default=0, doc="random seed")
    lod: int = arg(default=0, doc="level of detail (0 = full)")
    options: dict = arg(default={}, doc="GrowOptions fields")


@message("export.modules", ExportFile, long=True)
class ExportModules(Request):
    """Grow modules (Takikawa et al. 2025) in the crown of the assembled tree's lobes; a GLB of plain
    nodes sharing one mesh per module type."""

    session: str = arg(doc="session id")
    format: str = arg(default="glb", doc="glb (USD is not written yet)")
    seed: int = arg(default=0, doc="random seed")
    options: dict = arg(default={}, doc="ModularTreeOptions fields")


# == the reference page ================================================================================
def _type_text(cls: type, f: dataclasses.Field) -> str:
    if "dtype" in f.metadata:
        shape = "(" + ", ".join("N" if s is None else str(s) for s in f.metadata["shape"]) + ")"
        return f"array `{f.metadata['dtype']}` {shape}"
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


if __name__ == "__main__":
    sys.stdout.write(describe())
