"""An in-memory ``SessionPort`` for tests and the offline demo: same replies as the server, simple rules.

Simplifications (the real rules live on the server): recombination links two placements when the base
of one main branch lies within ``fake_rules.MERGE_DISTANCE`` of the other's main branch; a sketch stroke whose
ends meet is a lobe, any other stroke a branch; growth scatters twigs and leaves in the lobe hulls'
boxes, ``density`` times ``fake_rules.TWIGS_PER_LOBE`` per lobe; export writes an OBJ of branch polylines.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from arboretum_library.assembly import Assembly, LobeTransform, Placement
from arboretum_library.descriptors import describe, tags_for
from arboretum_library.errors import InputError
from arboretum_library.model import HBL, Example, Provenance
from arboretum_library.protocol import (
    Edit,
    ExportFile,
    GrownTree,
    RefineCloud,
    RefineState,
    SessionAssembly,
)

from .demo import demo_library
from .fake_rules import (
    as_example_structure,
    catalog_row,
    grow_twigs,
    recombine,
    single_lobe_hbl,
    sketch_example,
    world_structure,
)
from .refine_ops import insert_lobe, merge_lobes, remove_lobe, split_lobe
from .session_port import ProgressFn, _no_progress


class FakeSession:
    """Implements ``SessionPort`` over a dict of examples; one assembly with undo/redo stacks."""

    def __init__(self, library: dict[str, Example] | None = None) -> None:
        self.library = dict(demo_library() if library is None else library)
        self._assembly = Assembly()
        self._undo: list[Assembly] = []
        self._redo: list[Assembly] = []
        self._draft: HBL | None = None
        self._draft_undo: list[HBL] = []
        self._draft_redo: list[HBL] = []
        self.calls: list[str] = []
        """Names of the calls made, in order (tests read it)."""
        self.revision = 0

    # -- library -----------------------------------------------------------------------------------
    def list_library(self, species: str = "", tags: Sequence[str] = ()) -> list[dict]:
        self.calls.append("list_library")
        rows = [catalog_row(e) for e in self.library.values()]
        return [r for r in rows if (not species or r["species"] == species) and set(tags) <= set(r["tags"])]

    def search_library(self, query: str, limit: int = 50) -> list[dict]:
        self.calls.append("search_library")
        terms = query.lower().split()
        hits = []
        for row in (catalog_row(e) for e in self.library.values()):
            words = {row["id"].lower(), row["species"], *row["tags"]}
            matched = [t for t in terms if any(t in w for w in words)]
            if matched:
                hits.append({"id": row["id"], "score": len(matched) / len(terms), "matched": matched})
        return sorted(hits, key=lambda h: (-h["score"], h["id"]))[:limit]

    def get_example(self, example_id: str) -> Example:
        self.calls.append("get_example")
        sketched = {e.id: e for e in self._assembly.sketches}
        if example_id not in self.library and example_id not in sketched:
            raise InputError(f"example {example_id!r}: not in the library")
        return self.library.get(example_id) or sketched[example_id]

    # -- modeling ----------------------------------------------------------------------------------
    def assembly(self) -> SessionAssembly:
        return SessionAssembly(assembly=self._assembly, revision=self.revision,
                               can_undo=bool(self._undo), can_redo=bool(self._redo))

    def _commit(self, new: Assembly, label: str, instance: str = "", kinds: tuple = ()) -> Edit:
        sketched = {e.id: e for e in new.sketches}
        new, merged = recombine(new, lambda i: sketched.get(i) or self._lookup(i), instance)
        self._undo.append(self._assembly)
        self._redo.clear()
        self._assembly = new
        self.revision += 1
        self.calls.append(label)
        return Edit(revision=self.revision, label=label, instance=instance, merged=merged, kinds=kinds,
                    can_undo=True, can_redo=False)

    def _lookup(self, example_id: str) -> Example:
        return self.get_example(example_id)

    def _placement(self, instance: str) -> Placement:
        for p in self._assembly.placements:
            if p.instance == instance:
                return p
        raise InputError(f"instance {instance!r}: not in the assembly")

    def _replace(self, placement: Placement) -> Assembly:
        ps = tuple(placement if p.instance == placement.instance else p for p in self._assembly.placements)
        return dataclasses.replace(self._assembly, placements=ps)

    def add_example(self, example_id: str, T_world_example: np.ndarray, scale: float = 1.0) -> Edit:
        self.get_example(example_id)
        taken = {p.instance for p in self._assembly.placements}
        name = next(f"{example_id}#{k}" for k in range(1, 10_000) if f"{example_id}#{k}" not in taken)
        p = Placement(name, example_id, np.asarray(T_world_example, np.float64), float(scale))
        new = dataclasses.replace(self._assembly, placements=(*self._assembly.placements, p))
        return self._commit(new, "add_example", name)

    def transform_example(self, instance: str, T_world_example: np.ndarray, scale: float = 1.0) -> Edit:
        p = dataclasses.replace(self._placement(instance), T_world_example=np.asarray(T_world_example, np.float64),
                                scale=float(scale))
        return self._commit(self._replace(p), "transform_example", instance)

    def transform_lobe(self, instance: str, lobe: int, T_example_lobe: np.ndarray) -> Edit:
        p = self._placement(instance)
        if not 0 <= lobe < len(self.get_example(p.example_id).structure.lobes):
            raise InputError(f"lobe {lobe}: not a lobe of {instance!r}")
        keep = tuple(t for t in p.lobe_transforms if t.lobe != lobe)
        p = dataclasses.replace(p, lobe_transforms=(*keep, LobeTransform(lobe, np.asarray(T_example_lobe, float))))
        return self._commit(self._replace(p), "transform_lobe", instance)

    def delete_example(self, instance: str) -> Edit:
        self._placement(instance)
        a = self._assembly
        new = dataclasses.replace(a, placements=tuple(p for p in a.placements if p.instance != instance),
                                  merges=tuple(m for m in a.merges if instance not in (m.a, m.b)))
        return self._commit(new, "delete_example", instance)

    def sketch(self, strokes: Sequence[np.ndarray]) -> Edit:
        example, kinds = sketch_example(strokes, f"sketch-{len(self._assembly.sketches) + 1}")
        a = self._assembly
        p = Placement(f"{example.id}#1", example.id, np.eye(4))
        new = dataclasses.replace(a, sketches=(*a.sketches, example), placements=(*a.placements, p))
        return self._commit(new, "sketch", p.instance, tuple(kinds))

    def _step(self, src: list, dst: list, label: str) -> Edit:
        if not src:
            raise InputError(f"nothing to {label}")
        dst.append(self._assembly)
        self._assembly = src.pop()
        self.revision += 1
        self.calls.append(label)
        return Edit(revision=self.revision, label=label, can_undo=bool(self._undo), can_redo=bool(self._redo))

    def undo(self) -> Edit:
        return self._step(self._undo, self._redo, "undo")

    def redo(self) -> Edit:
        return self._step(self._redo, self._undo, "redo")

    def save(self) -> Assembly:
        return self._assembly

    def load(self, assembly: Assembly) -> SessionAssembly:
        self._commit(assembly, "load")
        return self.assembly()

    def grow(self, seed: int = 0, options: dict | None = None, progress: ProgressFn = _no_progress) -> GrownTree:
        hbls = [world_structure(self._lookup(p.example_id), p) for p in self._assembly.placements]
        if not hbls:
            raise InputError("grow: the assembly is empty; add an example first")
        tree = grow_twigs(hbls, seed, float((options or {}).get("density", 1.0)), progress)
        self.calls.append("grow")
        return tree

    def export_mesh(self, fmt: str = "glb", seed: int = 0, options: dict | None = None,
                    progress: ProgressFn = _no_progress) -> ExportFile:
        hbls = [world_structure(self._lookup(p.example_id), p) for p in self._assembly.placements]
        lines, n = [], 0
        for b in (b for h in hbls for b in h.branches):
            lines += [f"v {x:.4f} {y:.4f} {z:.4f}" for x, y, z in b.points]
            lines.append("l " + " ".join(str(n + i + 1) for i in range(len(b.points))))
            n += len(b.points)
        progress(1, 1, "export")
        data = np.frombuffer("\n".join(lines).encode() + b"\n", np.uint8)
        self.calls.append("export_mesh")
        return ExportFile(name="tree.obj", data=data, stats={"vertices": n, "format": "obj"})

    # -- refinement --------------------------------------------------------------------------------
    def _refined(self, hbl: HBL, label: str) -> RefineState:
        if self._draft is not None:
            self._draft_undo.append(self._draft)
            self._draft_redo.clear()
        self._draft = hbl
        self.calls.append(label)
        return self._refine_state()

    def _refine_state(self) -> RefineState:
        assert self._draft is not None
        return RefineState(hbl=self._draft, revision=len(self._draft_undo), can_undo=bool(self._draft_undo),
                           can_redo=bool(self._draft_redo))

    def _need_draft(self) -> HBL:
        if self._draft is None:
            raise InputError("refinement: open a scan first")
        return self._draft

    def refine_open(self, points: np.ndarray, labels: np.ndarray | None = None, species: str = "unknown",
                    progress: ProgressFn = _no_progress, name: str = "scan",
                    options: dict | None = None) -> RefineState:
        from .demo import demo_tree

        progress(0, 1, "decompose")
        self._draft, self._draft_undo, self._draft_redo = None, [], []
        hbl = demo_tree() if len(points) == 0 else single_lobe_hbl(np.asarray(points, float), labels)
        progress(1, 1, "decompose")
        return self._refined(hbl, "refine_open")

    def refine_points(self) -> RefineCloud:
        hbl = self._need_draft()
        lobe_of = np.full(len(hbl.points), -1, np.int32)
        for j, lb in enumerate(hbl.lobes):
            d = np.linalg.norm(hbl.points[:, None] - lb.points[None], axis=2) if len(lb.points) else None
            if d is not None:
                lobe_of[d.min(axis=1) < 1e-9] = j
        return RefineCloud(points=hbl.points.astype(np.float32), labels=hbl.labels, lobe_of=lobe_of)

    def remove_lobe(self, lobe: int) -> RefineState:
        return self._refined(remove_lobe(self._need_draft(), lobe), "remove_lobe")

    def insert_lobe(self, indices: np.ndarray) -> RefineState:
        return self._refined(insert_lobe(self._need_draft(), np.asarray(indices, np.int64)), "insert_lobe")

    def merge_lobes(self, lobes: Sequence[int]) -> RefineState:
        return self._refined(merge_lobes(self._need_draft(), list(lobes)), "merge_lobes")

    def split_lobe(self, lobe: int, strokes: Sequence[np.ndarray]) -> RefineState:
        return self._refined(split_lobe(self._need_draft(), lobe, strokes), "split_lobe")

    def refine_undo(self) -> RefineState:
        if not self._draft_undo:
            raise InputError("nothing to undo")
        self._draft_redo.append(self._need_draft())
        self._draft = self._draft_undo.pop()
        return self._refine_state()

    def refine_redo(self) -> RefineState:
        if not self._draft_redo:
            raise InputError("nothing to redo")
        self._draft_undo.append(self._need_draft())
        self._draft = self._draft_redo.pop()
        return self._refine_state()

    def refine_commit(self) -> tuple[list[str], tuple[str, ...]]:
        hbl = self._need_draft()
        ex = Example(f"refined-{len(self.library) + 1:04d}", as_example_structure(hbl),
                     Provenance("refined", "0" * 64), describe(as_example_structure(hbl)))
        self.library[ex.id] = dataclasses.replace(ex, tags=tags_for(ex.descriptors))
        return [ex.id], ()

    def close(self) -> None:
        self.calls.append("close")
