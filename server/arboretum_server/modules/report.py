"""What an instanced export reports: instances, types, sizes against a flat mesh, constraint statistics."""

from __future__ import annotations

from typing import Any

import numpy as np

from .export import Instances
from .tree import ModularTree


def size_report(inst: Instances, out_bytes: int, flat_bytes: int) -> dict[str, Any]:
    """Modules placed, types used, triangles, file sizes and the compression ratio flat / instanced."""
    return {
        "modules_placed": int(len(inst.module)),
        "types_used": int(len(np.unique(inst.module))),
        "triangles": inst.triangles,
        "bytes": int(out_bytes),
        "flat_bytes": int(flat_bytes),
        "compression": float(flat_bytes) / max(int(out_bytes), 1),
    }


def _range(values: np.ndarray) -> list[float] | None:
    v = values[np.isfinite(values)]
    return [float(v.min()), float(v.max())] if len(v) else None


def constraint_report(tree: ModularTree) -> dict[str, Any]:
    """The paper's constraints on a crown-grown tree: violation counts (``constraints.count_violations``,
    stored in ``tree.stats``) and the ranges actually used (branches only; the trunk is given)."""
    b = slice(1, None)
    ratio = tree.child_radius[b] / tree.parent_radius[b]
    return {
        "violations": dict(tree.stats.violations),
        "reached_fraction": float(tree.stats.reached_fraction),
        "iterations": int(tree.stats.iterations),
        "layers": int(tree.depth.max()) if len(tree.depth) else 0,
        "scale_range": _range(tree.scale[b]),
        "branch_angle_deg_range": _range(np.degrees(tree.branch_angle[b])),
        "max_child_over_parent_radius": float(np.nanmax(ratio)) if np.isfinite(ratio).any() else None,
    }


def describe(data: dict[str, Any]) -> str:
    """The human summary for the CLI: one line, plus one ``note:`` line per entry of ``data["notes"]``."""
    text = (f"wrote {data['out']} ({data['bytes']} bytes): {data['modules_placed']} modules of "
            f"{data['types_used']} types, {data['triangles']} triangles; flat mesh {data['flat_bytes']} bytes "
            f"(1:{data['compression']:.0f})")
    c = data.get("constraints")
    if c:
        bad = sum(c["violations"].values())
        text += f"; {bad} constraint violations, {100 * c['reached_fraction']:.0f}% attraction points reached"
    if "chamfer_fraction" in data:
        text += f"; Chamfer {100 * data['chamfer_fraction']:.3f}% of height"
    for note in data.get("notes", ()):
        text += f"\nnote: {note}"
    return text
