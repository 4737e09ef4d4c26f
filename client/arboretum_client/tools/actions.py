"""Tool actions: each submits one port call to the worker and applies the reply to the state.

The same actions serve hands, keyboard shortcuts, panels and scripts. Replies are applied on the main
thread (``Worker.drain``); nothing here waits. File reads and writes (load, save, export) run inside the
worker call, so ``on_done`` only updates the state.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from arboretum_client.net import Worker
from arboretum_library.assembly import Assembly
from arboretum_library.atomic import write_atomic
from arboretum_library.codec import load_record, save_record
from arboretum_library.errors import InputError
from arboretum_library.protocol import ALREADY_COMMITTED, Edit, RefineState, SessionAssembly

from .state import REFINEMENT, ClientState


def describe_error(exc: BaseException) -> str:
    """One line for a failure the user can cause (a file error names the file)."""
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror or exc}"
    return str(exc) or type(exc).__name__


def committed(ids: list[str], notes: tuple[str, ...]) -> str:
    """The status line after ``refine_commit``: the ids stored and the server's notes (a repeated commit
    of an unchanged draft stored nothing: its note says so instead of 'stored')."""
    repeat = [n for n in notes if ALREADY_COMMITTED in n]
    head = repeat[0] if repeat else f"stored {', '.join(ids)}"
    return "; ".join([head, *(n for n in notes if n not in repeat)])


class Actions:
    """Named operations over the session, wired to a ``ClientState``."""

    def __init__(self, state: ClientState, worker: Worker, clock=time.monotonic) -> None:
        self.state, self.worker, self.clock = state, worker, clock

    def _fail(self, what: str, say: str | None = None):
        """An error handler: the error kept in ``errors``, the status line ``say`` or 'WHAT failed: ...'."""
        def on_error(exc: BaseException) -> None:
            text = describe_error(exc)
            self.state.errors.append(f"{what}: {text}")
            self.state.say(say or f"{what} failed: {text}")
        return on_error

    def _submit(self, name: str, call, on_done, failed: str | None = None) -> int:
        """Run ``call`` on the worker, saying so; ``failed``: the status line if it fails (``_fail``)."""
        self.state.say(f"{name}...")
        return self.worker.submit(name, call, on_done, self._fail(name, failed))

    # -- library -----------------------------------------------------------------------------------
    def refresh_library(self, quiet: bool = False) -> None:
        """List the library again; ``quiet`` keeps the status line (a commit's ids stay readable)."""
        tag = self.state.tag_filter

        def call(port, _):
            return port.list_library(tags=(tag,) if tag else ())
        if quiet:
            self.worker.submit("list library", call, self._quiet_rows, self._fail("list library"))
        else:
            self._submit("list library", call, self._rows)

    def search(self, query: str) -> None:
        self.state.query = query
        if not query.strip():
            return self.refresh_library()

        def call(port, _):
            hits = port.search_library(query)
            rows = {r["id"]: r for r in port.list_library()}
            return [rows[h["id"]] for h in hits if h["id"] in rows]
        self._submit("search", call, self._rows)

    def _rows(self, rows: list[dict]) -> None:
        self.state.library = list(rows)
        self.state.say(f"{len(rows)} examples")

    def _quiet_rows(self, rows: list[dict]) -> None:
        self.state.library = list(rows)
        self.state.ui_version += 1

    def choose(self, example_id: str) -> None:
        """Choose a library example: fetched into the cache; the next select on empty space places it."""
        self.state.chosen = example_id
        self.fetch(example_id)
        self.state.say(f"chose {example_id}: select a spot to place it")

    def fetch(self, example_id: str) -> None:
        if example_id in self.state.examples:
            return
        self._submit("get example", lambda p, _: p.get_example(example_id), self._cache)

    def _cache(self, example) -> None:
        self.state.examples[example.id] = example
        self.state.touch_scene()

    # -- modeling ----------------------------------------------------------------------------------
    def _edit(self, name: str, call) -> int:
        def done(edit: Edit) -> None:
            self.state.revision, self.state.can_undo, self.state.can_redo = edit.revision, edit.can_undo, edit.can_redo
            now = self.clock()
            for inst in (*edit.merged, *( [edit.instance] if edit.merged else [])):
                self.state.merged_flash[inst] = now + 2.0
            msg = f"{edit.label or name}" + (f": merged with {', '.join(edit.merged)}" if edit.merged else "")
            if edit.kinds:
                msg += f" (strokes: {', '.join(edit.kinds)})"
            self.state.say(msg)
            self.sync()
        return self._submit(name, lambda p, _: call(p), done)

    def sync(self) -> None:
        """Fetch the assembly (and any examples it uses that are not cached)."""
        def call(port, _):
            reply: SessionAssembly = port.assembly()
            sketched = {e.id for e in reply.assembly.sketches}
            missing = {p.example_id for p in reply.assembly.placements} - set(self.state.examples) - sketched
            return reply, [port.get_example(i) for i in sorted(missing)]
        self.worker.submit("sync", call, self._synced, self._fail("sync"))

    def _synced(self, result) -> None:
        reply, examples = result
        for e in [*examples, *reply.assembly.sketches]:
            self.state.examples[e.id] = e
        s = self.state
        s.assembly, s.revision, s.can_undo, s.can_redo = reply.assembly, reply.revision, reply.can_undo, reply.can_redo
        live = {p.instance for p in reply.assembly.placements}
        s.selection = [n for n in s.selection if n.split("/")[0].removeprefix("inst:") in live]
        s.touch_scene()

    def add_example(self, example_id: str, T_world_example: np.ndarray, scale: float = 1.0) -> int:
        self.fetch(example_id)
        return self._edit("add example", lambda p: p.add_example(example_id, T_world_example, scale))

    def transform_example(self, instance: str, T: np.ndarray, scale: float) -> int:
        return self._edit("transform example", lambda p: p.transform_example(instance, T, scale))

    def transform_lobe(self, instance: str, lobe: int, T: np.ndarray) -> int:
        return self._edit("transform lobe", lambda p: p.transform_lobe(instance, lobe, T))

    def delete_example(self, instance: str) -> int:
        return self._edit("delete example", lambda p: p.delete_example(instance))

    def sketch(self) -> int | None:
        strokes, self.state.strokes = list(self.state.strokes), []
        if not strokes:
            self.state.say("sketch: draw strokes first (hold the trigger)")
            return None
        self.state.touch_scene()
        return self._edit("sketch", lambda p: p.sketch(strokes))

    def undo(self) -> None:
        if self.state.mode == REFINEMENT:
            self._refine("undo", lambda p: p.refine_undo())
        else:
            self._edit("undo", lambda p: p.undo())

    def redo(self) -> None:
        if self.state.mode == REFINEMENT:
            self._refine("redo", lambda p: p.refine_redo())
        else:
            self._edit("redo", lambda p: p.redo())

    def save(self, path: str | os.PathLike) -> None:
        """Fetch the assembly and write it to ``path`` on the worker thread (never in the frame loop); an
        unwritable path is a status line."""
        def call(port, _):
            assembly: Assembly = port.save()
            try:
                save_record(path, assembly)
            except OSError as exc:
                raise InputError(f"cannot write {path} ({exc.strerror or exc})") from None

        self._submit("save", call, lambda _none: self.state.say(f"saved {Path(path).name}"))

    def load(self, path: str | os.PathLike) -> None:
        """Read ``path`` on the worker thread (never in the frame loop); a missing or bad file is a
        status line and leaves the session as it was."""
        def call(port, _):
            try:
                assembly = load_record(path, Assembly)
            except OSError as exc:
                raise InputError(f"{path}: cannot read it ({exc.strerror or exc})") from None
            return port.load(assembly)

        def done(_reply) -> None:
            self.state.say(f"loaded {Path(path).name}")
            self.sync()
        self._submit("load", call, done)

    def grow(self, seed: int = 0) -> None:
        density = self.state.density

        def done(tree) -> None:
            self.state.grown = tree
            self.state.touch_scene()
            self.state.say(f"grown: {len(tree.positions)} nodes, {len(tree.leaf_centres)} leaves")
        self._submit("grow", lambda p, progress: p.grow(seed, {"density": density}, progress), done)

    def set_density(self, value: float) -> None:
        self.state.density = float(np.clip(value, 0.1, 4.0))
        self.state.say(f"density {self.state.density:.2f}")

    def export(self, folder: str | os.PathLike, fmt: str = "glb") -> None:
        """Export the tree and write it into ``folder`` on the worker thread (never in the frame loop);
        an unwritable folder is a status line and writes nothing."""
        density = self.state.density

        def call(port, progress):
            reply = port.export_mesh(fmt, 0, {"density": density}, progress)
            path = Path(folder) / reply.name
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                write_atomic(path, reply.data.tobytes())
            except OSError as exc:
                raise InputError(f"cannot write {path} ({exc.strerror or exc})") from None
            return path, len(reply.data)

        def done(result: tuple[Path, int]) -> None:
            path, size = result
            self.state.exported.append(str(path))
            self.state.say(f"exported {path.name} ({size} bytes)")
        self._submit("export", call, done)

    # -- refinement --------------------------------------------------------------------------------
    def _refine(self, name: str, call) -> int:
        def done(reply: RefineState) -> None:
            s = self.state
            s.draft, s.selection, s.point_selection = reply.hbl, [], np.zeros(0, np.int64)
            s.strokes = []  # used by this edit, or drawn for another: a later split must not reuse them
            s.can_undo, s.can_redo, s.refine_revision = reply.can_undo, reply.can_redo, reply.revision
            s.say(f"{name}: {len(reply.hbl.lobes)} lobes")
            self.worker.submit("points", lambda p, _: p.refine_points(), self._cloud, self._fail("points"))
            s.touch_scene()
        return self._submit(name, lambda p, progress=None: call(p), done)

    def _cloud(self, cloud) -> None:
        self.state.cloud = cloud
        self.state.touch_scene()

    def refine_open(self, points: np.ndarray, labels: np.ndarray | None = None, species: str = "unknown",
                    name: str = "scan", options: dict | None = None) -> None:
        # without a scan the server's "0 usable points" would not say what is missing
        missing = None if len(points) else "refinement: no scan to refine; start the client with --scan FILE"
        self._submit("decompose", lambda p, progress: p.refine_open(points, labels, species, progress, name=name,
                                                                    options=options),
                     lambda r: self._refine("open", lambda _p: r), missing)

    def remove_lobe(self, lobe: int) -> int:
        return self._refine("remove lobe", lambda p: p.remove_lobe(lobe))

    def insert_lobe(self, indices: np.ndarray) -> int:
        idx = np.asarray(indices, np.int64)
        return self._refine("insert lobe", lambda p: p.insert_lobe(idx))

    def merge_lobes(self, lobes: list[int]) -> int:
        return self._refine("merge lobes", lambda p: p.merge_lobes(lobes))

    def split_lobe(self, lobe: int, strokes: list[np.ndarray]) -> int:
        return self._refine("split lobe", lambda p: p.split_lobe(lobe, strokes))

    def commit_refinement(self) -> None:
        if self.state.draft is None:
            self.state.say("commit: no refinement draft (Tab opens the --scan in refinement)")
            return
        self._submit("commit", lambda p, _: p.refine_commit(),
                     lambda r: (self.state.say(committed(*r)), self.refresh_library(quiet=True)))
