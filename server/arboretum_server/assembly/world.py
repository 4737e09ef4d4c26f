"""Placed examples in the world frame, and ``assembly_to_hbl``: one HBL from a whole assembly.

A placement's structure goes to the world in two steps: each lobe transform (a similarity about the
lobe centre, example frame; the feeding branch bends along so its tip follows the lobe), then the
placement's uniform ``scale`` and rigid ``T_world_example``. Merge links then join placements as
Algorithm 1 joins branches: ``b``'s main branch keeps its vertices from ``vertex_b`` on, starts from
``a``'s vertex ``vertex_a`` by a new edge (its first vertex moved by Eq. 1), and ``b``'s secondary
branches that hung on the merged part move to the nearest vertex of ``a``'s main branch.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from arboretum_library.assembly import Assembly, Placement
from arboretum_library.errors import InputError
from arboretum_library.geometry import apply_transform, polyline_lengths
from arboretum_library.model import HBL, Branch, Example, Level, Lobe

ExampleSource = Callable[[str], Example]
"""Example id -> Example (library examples and the assembly's sketches)."""


def resolver(assembly: Assembly, library_get: ExampleSource) -> ExampleSource:
    """A source that finds the assembly's sketched examples first, then asks ``library_get``."""
    sketches = {e.id: e for e in assembly.sketches}
    return lambda id_: sketches[id_] if id_ in sketches else library_get(id_)


def _lobe_moved(structure: HBL, lobe: int, T: np.ndarray) -> tuple[Lobe, Branch | None]:
    lb = structure.lobes[lobe]
    c = lb.centre

    def move(p: np.ndarray) -> np.ndarray:
        return (p - c) @ T[:3, :3].T + c + T[:3, 3] if len(p) else p

    new = Lobe(move(lb.points), move(lb.hull_vertices), lb.hull_faces, c + T[:3, 3], lb.branch)
    if lb.branch < 0:
        return new, None
    b = structure.branches[lb.branch]
    s = polyline_lengths(b.points)
    w = (s / s[-1])[:, None] if s[-1] > 0 else np.linspace(0, 1, len(s))[:, None]
    return new, Branch(b.points + w * T[:3, 3], b.radii, b.parent, b.parent_vertex, b.level)


def placed_structure(p: Placement, ex: Example) -> HBL:
    """The example's structure with ``p``'s lobe transforms, scale and transform applied (world frame)."""
    s = ex.structure
    branches, lobes = list(s.branches), list(s.lobes)
    for lt in p.lobe_transforms:
        if not 0 <= lt.lobe < len(lobes):
            raise InputError(f"placement {p.instance!r}: lobe {lt.lobe} does not exist in {ex.id!r}")
        lobes[lt.lobe], moved = _lobe_moved(HBL(s.root, tuple(branches), tuple(lobes)), lt.lobe, lt.T_example_lobe)
        if moved is not None:
            branches[lobes[lt.lobe].branch] = moved
    T = p.T_world_example.copy()
    T[:3, :3] *= p.scale

    def w(x: np.ndarray) -> np.ndarray:
        return apply_transform(T, x) if len(x) else x.reshape(0, 3)

    return HBL(
        w(s.root[None])[0],
        tuple(Branch(w(b.points), b.radii * p.scale, b.parent, b.parent_vertex, b.level) for b in branches),
        tuple(Lobe(w(lb.points), w(lb.hull_vertices), lb.hull_faces, w(lb.centre[None])[0], lb.branch) for lb in lobes),
    )


def main_world(p: Placement, ex: Example) -> np.ndarray:
    """(N, 3) the placement's main branch in the world frame (lobe transforms do not move it)."""
    T = p.T_world_example.copy()
    T[:3, :3] *= p.scale
    return apply_transform(T, ex.structure.branches[0].points)


def merge_order(assembly: Assembly) -> list[Placement]:
    """Placements with every merge link's ``a`` before its ``b`` (unlinked ones in assembly order)."""
    parent = {m.b: m.a for m in assembly.merges}
    by_name = {p.instance: p for p in assembly.placements}
    order: list[Placement] = []
    seen: set[str] = set()

    def visit(name: str, depth: int = 0) -> None:
        if name in seen or depth > len(by_name):
            return
        if name in parent:
            visit(parent[name], depth + 1)
        seen.add(name)
        order.append(by_name[name])

    for p in assembly.placements:
        visit(p.instance)
    return order


def assembly_to_hbl(assembly: Assembly, library_get: ExampleSource) -> HBL:
    """One HBL of the whole assembly, world frame, merge links applied (what growth and export use)."""
    if not assembly.placements:
        raise InputError("the assembly is empty: place or sketch at least one example")
    source = resolver(assembly, library_get)
    links = {m.b: m for m in assembly.merges}
    branches: list[Branch] = []
    lobes: list[Lobe] = []
    main_of: dict[str, tuple[int, int]] = {}
    """instance -> (index of its main branch, vertices its main lost to a merge minus the new first one)"""
    for p in merge_order(assembly):
        s = placed_structure(p, source(p.example_id))
        base = len(branches)
        link = links.get(p.instance)
        if link is None:
            remap, shift = _append(s, base, branches), 0
        else:
            a_index, a_shift = main_of[link.a]
            va = max(link.vertex_a - a_shift, 0)
            remap = _attach(s, branches[a_index], a_index, va, link.vertex_b, base, branches)
            shift = max(link.vertex_b, 0) - 1
        main_of[p.instance] = (base, shift)
        lobes += [Lobe(lb.points, lb.hull_vertices, lb.hull_faces, lb.centre, remap(lb.branch)) for lb in s.lobes]
    root = branches[main_of[merge_order(assembly)[0].instance][0]].points[0]
    return HBL(root, tuple(branches), tuple(lobes))


def _append(s: HBL, base: int, out: list[Branch]) -> Callable[[int], int]:
    for b in s.branches:
        parent = b.parent + base if b.parent >= 0 else -1
        out.append(Branch(b.points, b.radii, parent, b.parent_vertex, b.level))
    return lambda j: j + base if j >= 0 else -1


def _attach(s: HBL, a_main: Branch, a_index: int, vertex_a: int, vertex_b: int, base: int,
            out: list[Branch]) -> Callable[[int], int]:
    """Append ``s`` with its main branch merged into ``a_main`` (Algorithm 1 across examples)."""
    from arboretum_server.decompose.merge import eq1

    main = s.branches[0]
    k = int(np.clip(vertex_b, 0, len(main.points) - 1))
    va = int(np.clip(vertex_a, 0, len(a_main.points) - 1))
    tail = main.points[k:].copy()
    if len(tail) >= 2:
        tail[0] = eq1(a_main.points[va], tail[0], tail[1])
    pts = np.vstack([a_main.points[va], tail])
    radii = np.r_[min(a_main.radii[va], main.radii[k]), main.radii[k:]]
    out.append(Branch(pts, radii, a_index, va, Level.MAIN))
    for b in s.branches[1:]:
        parent, pv = b.parent + base, b.parent_vertex
        if b.parent == 0:
            if pv >= k:
                pv = pv - k + 1
            else:
                parent = a_index
                pv = int(np.argmin(np.linalg.norm(a_main.points - main.points[pv], axis=1)))
        out.append(Branch(b.points, b.radii, parent if b.parent >= 0 else -1, pv, b.level))
    return lambda j: j + base if j >= 0 else -1


def load_structure(path: str, library: str | None) -> HBL:
    """An HBL from a record .npz holding an HBL, or an Assembly resolved against the example ``library``.

    What the commands that consume a tree (``grow``, ``modules``) accept as input.
    """
    from arboretum_library.codec import load_record, record_kind
    from arboretum_library.store import Library

    kind = record_kind(path)
    if kind == "HBL":
        return load_record(path, HBL)
    if kind != "Assembly":
        raise InputError(f"{path}: holds a {kind!r} record; expected an HBL or an Assembly")
    if library is None:
        raise InputError(f"{path}: an Assembly record needs --library LIB (the examples it places)")
    lib = Library.open_reading(library)
    try:
        return assembly_to_hbl(load_record(path, Assembly), lib.get)
    finally:
        lib.close()
