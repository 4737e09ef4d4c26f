"""``SessionPort`` over ``arboretum_library.remote.Remote``: one server session per client.

Everything here runs on the network worker thread (one socket, one thread). Calls that ``Remote`` has
no helper for (save/load, refinement) are sent as protocol requests through ``Remote.call``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly
from arboretum_library.model import Example

from .session_port import ProgressFn, _no_progress, strokes_to_arrays

LONG_TIMEOUT = 600.0
"""Seconds a long job (grow, export, decompose) may stay silent between progress events."""


class RemoteSession:
    """Implements ``SessionPort`` with a ``Remote`` connection and a new (or given) session id."""

    def __init__(self, endpoint: str, name: str = "client", timeout: float = 10.0, session: str | None = None,
                 curve: str | None = None) -> None:
        from arboretum_library.remote import Remote

        self.remote = Remote(endpoint, timeout=timeout, curve=curve)
        self.session = session or self.remote.new_session(name).session

    # -- library -----------------------------------------------------------------------------------
    def list_library(self, species: str = "", tags: Sequence[str] = ()) -> list[dict]:
        return self.remote.library_list(species, tags)

    def search_library(self, query: str, limit: int = 50) -> list[dict]:
        return self.remote.search(query, limit)

    def get_example(self, example_id: str) -> Example:
        return self.remote.get_example(example_id)

    # -- modeling ----------------------------------------------------------------------------------
    def assembly(self) -> P.SessionAssembly:
        return self.remote.assembly(self.session)

    def add_example(self, example_id: str, T_world_example: np.ndarray, scale: float = 1.0) -> P.Edit:
        return self.remote.add_example(self.session, example_id, T_world_example, scale)

    def transform_example(self, instance: str, T_world_example: np.ndarray, scale: float = 1.0) -> P.Edit:
        return self.remote.transform_example(self.session, instance, T_world_example, scale)

    def transform_lobe(self, instance: str, lobe: int, T_example_lobe: np.ndarray) -> P.Edit:
        return self.remote.transform_lobe(self.session, instance, lobe, T_example_lobe)

    def delete_example(self, instance: str) -> P.Edit:
        return self.remote.delete_placement(self.session, instance)

    def sketch(self, strokes: Sequence[np.ndarray]) -> P.Edit:
        return self.remote.sketch(self.session, list(strokes))

    def undo(self) -> P.Edit:
        return self.remote.undo(self.session)

    def redo(self) -> P.Edit:
        return self.remote.redo(self.session)

    def save(self) -> Assembly:
        return self.remote.call(P.SessionSave(session=self.session)).assembly

    def load(self, assembly: Assembly) -> P.SessionAssembly:
        info = self.remote.call(P.SessionLoad(assembly=assembly, name="loaded"))
        self.session = info.session
        return self.assembly()

    def grow(self, seed: int = 0, options: dict | None = None, progress: ProgressFn = _no_progress) -> P.GrownTree:
        return self.remote.grow(self.session, seed, options, progress=progress, timeout=LONG_TIMEOUT)

    def export_mesh(self, fmt: str = "glb", seed: int = 0, options: dict | None = None,
                    progress: ProgressFn = _no_progress) -> P.ExportFile:
        return self.remote.export_mesh(self.session, fmt, seed, 0, options, progress=progress, timeout=LONG_TIMEOUT)

    # -- refinement --------------------------------------------------------------------------------
    def refine_open(self, points: np.ndarray, labels: np.ndarray | None = None, species: str = "unknown",
                    progress: ProgressFn = _no_progress, name: str = "scan",
                    options: dict | None = None) -> P.RefineState:
        req = P.RefineOpen(session=self.session, points=np.asarray(points, np.float64), labels=labels,
                           species=species, name=name, options=dict(options or {}))
        return self.remote.call(req, progress=progress, timeout=LONG_TIMEOUT)

    def refine_points(self) -> P.RefineCloud:
        return self.remote.call(P.RefinePoints(session=self.session))

    def remove_lobe(self, lobe: int) -> P.RefineState:
        return self.remote.call(P.RemoveLobe(session=self.session, lobe=int(lobe)))

    def insert_lobe(self, indices: np.ndarray) -> P.RefineState:
        return self.remote.call(P.InsertLobe(session=self.session, indices=np.asarray(indices, np.int64)))

    def merge_lobes(self, lobes: Sequence[int]) -> P.RefineState:
        return self.remote.call(P.MergeLobes(session=self.session, lobes=tuple(int(j) for j in lobes)))

    def split_lobe(self, lobe: int, strokes: Sequence[np.ndarray]) -> P.RefineState:
        pts, sizes = strokes_to_arrays(strokes)
        return self.remote.call(P.SplitLobe(session=self.session, lobe=int(lobe), stroke_points=pts,
                                            stroke_sizes=sizes))

    def refine_undo(self) -> P.RefineState:
        return self.remote.call(P.RefineUndo(session=self.session))

    def refine_redo(self) -> P.RefineState:
        return self.remote.call(P.RefineRedo(session=self.session))

    def refine_commit(self) -> tuple[list[str], tuple[str, ...]]:
        r = self.remote.call(P.RefineCommit(session=self.session))
        return list(r.ids), tuple(r.notes)

    def close(self) -> None:
        self.remote.close()
