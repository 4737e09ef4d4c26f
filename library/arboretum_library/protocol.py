"""Every message between an Arboretum client and server, as typed records both ends import.

A message is a frozen dataclass registered under its wire ``TYPE``. Scalar fields (str, int, float,
bool, tuples of them, JSON maps) travel in the msgpack header's body; array fields travel as raw frames
(``wire``) and declare their dtype and shape, which are checked (and the dtype normalised) when the
message is built, on either end; record fields (``HBL``, ``Example``, ``Assembly``) travel through
``codec.flatten`` as body metadata plus one array frame per record array. A request names its reply
type; requests marked ``LONG`` run as jobs that send ``Progress`` events (same request id) before
their reply, and may be cancelled with ``Cancel``. Any failure comes back as an ``Error`` reply with a
``code`` and a message.

Compatibility: a received array is cast to the dtype its field declares when it fits the kind (float
takes float and int, int takes int, ...), so widening a field within its kind (``refine.cloud.points``
went from <f4 to <f8 in session 12) needs no new ``PROTOCOL_VERSION``: each side reads the other's frames
at its own declared dtype (an older client still gets float32). A change of kind would need one.

``python -m arboretum_library.protocol > docs/protocol.md`` writes the reference from this module.
The machinery (base classes, field specs and checks, registry, wire conversion, the reference page)
lives in ``protocol_base``; what callers use of it is re-exported here (``import X as X``).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import __version__
from .assembly import Assembly
from .errors import ProtocolError
from .model import HBL, Example
from .protocol_base import MAX_STRING as MAX_STRING
from .protocol_base import RECORDS as RECORDS
from .protocol_base import REGISTRY as REGISTRY
from .protocol_base import Msg, Reply, Request, arg, array, describe, message
from .protocol_base import UnknownType as UnknownType
from .protocol_base import error_code as error_code
from .protocol_base import from_message as from_message
from .protocol_base import parse as parse
from .protocol_base import to_frames as to_frames
from .wire import PROTOCOL_VERSION


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


@dataclass(frozen=True, kw_only=True)
class SessionRequest(Request):
    """A request about one server session; ``session`` comes first in every such request."""

    session: str = arg(doc="session id")


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
    ready: bool = arg(True, doc="False while the server is still importing its heavy modules after start-up "
                      "(the first seconds; replies are slower until then)")


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
    notes: tuple[str, ...] = arg(default=(), doc="what the decomposition did that the user may not expect "
                                                 "(a second trunk, a straight line, all foliage, counts not met, "
                                                 "a species not in Table 2; refine.commit: not the counts)")


ALREADY_COMMITTED = "was committed already"
"""Words of the note by which ``refine.commit`` says it stored nothing (the draft is unchanged since its
last commit); the client's status line looks for them."""


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
class SessionGet(SessionRequest):
    pass


@message("session.save", SessionAssembly)
class SessionSave(SessionRequest):
    """The session's assembly, to keep client-side (load it back with session.load)."""



@message("session.load", SessionInfo)
class SessionLoad(Request):
    """A new session holding ``assembly``."""

    assembly: Assembly = arg(doc="an assembly saved earlier")
    name: str = arg(default="", doc="a name for people")


@message("session.close", Ack)
class SessionClose(SessionRequest):
    """Delete the session and its autosave."""



@message("session.hbl_reply")
class SessionHBLReply(Reply):
    hbl: HBL = arg(doc="the assembled tree, merges applied, world frame")


@message("session.hbl", SessionHBLReply)
class SessionHBL(SessionRequest):
    """The assembled HBL (``assembly_to_hbl``): what growth and export consume."""



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
class Undo(SessionRequest):
    pass


@message("session.redo", Edit)
class Redo(SessionRequest):
    pass


# -- assembly (VRTree 3.5) ------------------------------------------------------------------------------
@message("assembly.add", Edit)
class AddExample(SessionRequest):
    """Select example: place a library example (recombination runs afterwards)."""

    example_id: str = arg(doc="library (or sketched) example id")
    T_world_example: np.ndarray = array(*F8_44, "(4, 4) rigid transform, example -> world")
    scale: float = arg(default=1.0, doc="uniform scale in the example frame")
    instance: str = arg(default="", doc="placement name ('' = generated)")


@message("assembly.transform", Edit)
class TransformExample(SessionRequest):
    """Transform example: move, turn and scale a placement (recombination runs afterwards)."""

    instance: str = arg(doc="placement name")
    T_world_example: np.ndarray = array(*F8_44, "(4, 4) new rigid transform, example -> world")
    scale: float = arg(default=1.0, doc="new uniform scale")


@message("assembly.transform_lobe", Edit)
class TransformLobe(SessionRequest):
    """Transform lobe: a similarity about the lobe centre, in the example frame."""

    instance: str = arg(doc="placement name")
    lobe: int = arg(doc="lobe index in the example")
    T_example_lobe: np.ndarray = array(*F8_44, "(4, 4) rotation, uniform scale, translation")


@message("assembly.delete", Edit)
class DeleteExample(SessionRequest):
    instance: str = arg(doc="placement name")


@message("assembly.sketch", Edit)
class SketchExample(SessionRequest):
    """Sketch new example: strokes (world frame) recognised as branches or lobes become an example."""

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
class RefineOpen(SessionRequest):
    """Decompose a scan into the session's refinement draft."""

    points: np.ndarray = array("<f8", (None, 3), "(N, 3) scan points, metres, Z up")
    labels: np.ndarray | None = array("|u1", (None,), "(N,) WOOD 0 / LEAF 1, optional", default=None)
    name: str = arg(default="scan", doc="source name")
    species: str = arg(default="unknown", doc="species")
    options: dict = arg(default={}, doc="DecomposeOptions fields")


@message("refine.cloud")
class RefineCloud(Reply):
    points: np.ndarray = array("<f8", (None, 3), "(N, 3) the draft's points, output frame (float64: a scan "
                               "kept in its own units at UTM coordinates loses up to 0.25 m in float32)")
    labels: np.ndarray = array("|u1", (None,), "(N,) WOOD 0 / LEAF 1")
    lobe_of: np.ndarray = array("<i4", (None,), "(N,) lobe of each point, -1 for none")


@message("refine.points", RefineCloud)
class RefinePoints(SessionRequest):
    """Send the draft's point cloud (to select points and draw split strokes on)."""



@message("refine.remove_lobe", RefineState)
class RemoveLobe(SessionRequest):
    lobe: int = arg(doc="lobe index")


@message("refine.insert_lobe", RefineState)
class InsertLobe(SessionRequest):
    indices: np.ndarray = array("<i8", (None,), "(M,) selected point indices")


@message("refine.merge_lobes", RefineState)
class MergeLobes(SessionRequest):
    lobes: tuple[int, ...] = arg(doc="two or more lobe indices")


@message("refine.split_lobe", RefineState)
class SplitLobe(SessionRequest):
    lobe: int = arg(doc="lobe index")
    stroke_points: np.ndarray = array("<f8", (None, 3), "(P, 3) stroke samples, output frame")
    stroke_sizes: np.ndarray = array("<i8", (None,), "(K,) samples per stroke; one new lobe each")
    seed: int = arg(default=0, doc="k-means seed")


@message("refine.undo", RefineState)
class RefineUndo(SessionRequest):
    pass


@message("refine.redo", RefineState)
class RefineRedo(SessionRequest):
    pass


@message("refine.commit", LibraryImported)
class RefineCommit(SessionRequest):
    """Split the refined HBL into examples and add them to the library."""



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
class Grow(SessionRequest):
    """Grow twigs and leaves in the lobes of the assembled tree (VRTree Eq. 2)."""

    seed: int = arg(default=0, doc="random seed (same seed, same tree)")
    options: dict = arg(default={}, doc="GrowOptions fields (density, leaf_density, step, alpha, beta, ...)")


@message("export.file")
class ExportFile(Reply):
    name: str = arg(doc="suggested file name")
    data: np.ndarray = array("|u1", (None,), "the file's bytes")
    stats: dict = arg(default={}, doc="counts (triangles, leaves, ...)")


@message("export.mesh", ExportFile, long=True)
class ExportMesh(SessionRequest):
    """Grow and mesh the assembled tree and return the file (glb, obj as zip, or ply)."""

    format: str = arg(default="glb", doc="glb, obj or ply")
    seed: int = arg(default=0, doc="random seed")
    lod: int = arg(default=0, doc="level of detail (0 = full)")
    options: dict = arg(default={}, doc="GrowOptions fields")


@message("export.modules", ExportFile, long=True)
class ExportModules(SessionRequest):
    """Grow modules (Takikawa et al. 2025) in the crown of the assembled tree's lobes, and write them."""

    format: str = arg(default="glb", doc="glb (plain nodes sharing one mesh per module type), glb-instanced "
                      "(EXT_mesh_gpu_instancing), usdc or usda (UsdGeom.PointInstancer)")
    seed: int = arg(default=0, doc="random seed")
    options: dict = arg(default={}, doc="ModularTreeOptions fields")


if __name__ == "__main__":
    sys.stdout.write(describe())
