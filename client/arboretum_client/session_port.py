"""What the interactive client needs from a server session: a small ``SessionPort`` protocol.

The client never talks to sockets itself: every call below runs on the network worker thread
(``net.Worker``), never inside the frame loop. Two implementations exist: ``FakeSession``
(``session_fake.py``, in memory, for tests and the offline demo) and ``RemoteSession`` (an adapter over
``arboretum_library.remote`` once that module exists). Replies reuse the wire records of
``arboretum_library.protocol`` (``Edit``, ``SessionAssembly``, ``RefineState``, ``RefineCloud``,
``GrownTree``, ``ExportFile``), so both implementations return exactly what the server would send.

Long calls (``grow``, ``export_mesh``, ``refine_open``) take a ``progress(done, total, message)``
callback, called on the worker thread.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from arboretum_library.assembly import Assembly
from arboretum_library.model import Example
from arboretum_library.protocol import (
    Edit,
    ExportFile,
    GrownTree,
    RefineCloud,
    RefineState,
    SessionAssembly,
)

ProgressFn = Callable[[float, float, str], None]
"""progress(done, total, message); total 0 means unknown."""


def _no_progress(done: float, total: float, message: str) -> None:
    """The default progress callback: ignore."""


@runtime_checkable
class SessionPort(Protocol):
    """One client's view of one server session (an assembly plus an optional refinement draft)."""

    # -- library -----------------------------------------------------------------------------------
    def list_library(self, species: str = "", tags: Sequence[str] = ()) -> list[dict]:
        """Catalog rows: id, species, source, tags, lobe_count, curvature, length, spread, height."""
        ...

    def search_library(self, query: str, limit: int = 50) -> list[dict]:
        """Hits best first: id, score, matched terms."""
        ...

    def get_example(self, example_id: str) -> Example: ...

    # -- modeling ----------------------------------------------------------------------------------
    def assembly(self) -> SessionAssembly:
        """The session's assembly, revision and undo/redo availability."""
        ...

    def add_example(self, example_id: str, T_world_example: np.ndarray, scale: float = 1.0) -> Edit: ...

    def transform_example(self, instance: str, T_world_example: np.ndarray, scale: float = 1.0) -> Edit: ...

    def transform_lobe(self, instance: str, lobe: int, T_example_lobe: np.ndarray) -> Edit: ...

    def delete_example(self, instance: str) -> Edit: ...

    def sketch(self, strokes: Sequence[np.ndarray]) -> Edit:
        """Strokes (each (P, 3) world points) become a new example; ``Edit.kinds`` says what each was."""
        ...

    def undo(self) -> Edit: ...

    def redo(self) -> Edit: ...

    def save(self) -> Assembly: ...

    def load(self, assembly: Assembly) -> SessionAssembly: ...

    def grow(self, seed: int = 0, options: dict | None = None, progress: ProgressFn = _no_progress) -> GrownTree:
        """Twigs and leaves by space colonization in the lobes; ``options`` e.g. {'density': 1.0}."""
        ...

    def export_mesh(self, fmt: str = "glb", seed: int = 0, options: dict | None = None,
                    progress: ProgressFn = _no_progress) -> ExportFile: ...

    # -- refinement --------------------------------------------------------------------------------
    def refine_open(self, points: np.ndarray, labels: np.ndarray | None = None, species: str = "unknown",
                    progress: ProgressFn = _no_progress, name: str = "scan",
                    options: dict | None = None) -> RefineState:
        """Decompose a scan (``name``: its file name, the committed examples' source; ``options``:
        ``DecomposeOptions`` fields, e.g. n_main, n_lobes) into a draft HBL to refine."""
        ...

    def refine_points(self) -> RefineCloud: ...

    def remove_lobe(self, lobe: int) -> RefineState: ...

    def insert_lobe(self, indices: np.ndarray) -> RefineState: ...

    def merge_lobes(self, lobes: Sequence[int]) -> RefineState: ...

    def split_lobe(self, lobe: int, strokes: Sequence[np.ndarray]) -> RefineState: ...

    def refine_undo(self) -> RefineState: ...

    def refine_redo(self) -> RefineState: ...

    def refine_commit(self) -> tuple[list[str], tuple[str, ...]]:
        """Store the refined draft's examples in the library; their ids and the server's notes (a repeated
        commit of an unchanged draft stores nothing and answers the first ids, with a note)."""
        ...

    def close(self) -> None: ...


def strokes_to_arrays(strokes: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Stroke list -> (all points (P, 3) float64, samples per stroke (K,) int64), the wire layout."""
    arrs = [np.asarray(s, np.float64).reshape(-1, 3) for s in strokes]
    if not arrs:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    return np.concatenate(arrs), np.array([len(a) for a in arrs], np.int64)
