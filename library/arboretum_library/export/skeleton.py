"""Skeleton JSON: a tree graph with radii, in the world frame (right-handed, Z up, metres).

    {"format": "arboretum-skeleton", "version": 1, "frame": "...", "up": [0, 0, 1],
     "nodes": N, "positions": [[x, y, z], ...], "radii": [...], "parents": [...], "levels": [...]}

``parents[i]`` is -1 for the root and otherwise an index < i; ``levels`` are 0 main, 1 secondary, 2 twig.
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from arboretum_library.atomic import write_atomic
from arboretum_library.errors import InputError

FORMAT = "arboretum-skeleton"


def skeleton_dict(positions: np.ndarray, radii: np.ndarray, parents: np.ndarray,
                  levels: np.ndarray | None = None) -> dict[str, Any]:
    """JSON-able dict of a skeleton (positions rounded to 0.1 mm, radii to 1 µm)."""
    d: dict[str, Any] = {
        "format": FORMAT, "version": 1, "frame": "right-handed, Z up, metres", "up": [0, 0, 1],
        "nodes": int(len(positions)),
        "positions": np.round(np.asarray(positions, np.float64), 4).tolist(),
        "radii": np.round(np.asarray(radii, np.float64), 6).tolist(),
        "parents": np.asarray(parents, np.int64).tolist(),
    }
    if levels is not None:
        d["levels"] = np.asarray(levels, np.int64).tolist()
    return d


def write_skeleton_json(path: str | os.PathLike, positions: np.ndarray, radii: np.ndarray,
                        parents: np.ndarray, levels: np.ndarray | None = None) -> int:
    data = json.dumps(skeleton_dict(positions, radii, parents, levels), separators=(",", ":")).encode()
    write_atomic(path, data)
    return len(data)


def read_skeleton_json(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Arrays of a skeleton JSON written by ``write_skeleton_json``."""
    try:
        d = json.loads(open(path, "rb").read())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a readable skeleton JSON ({exc})") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise InputError(f"{path}: not an {FORMAT} file")
    out = {"positions": np.array(d["positions"], np.float64).reshape(-1, 3),
           "radii": np.array(d["radii"], np.float64), "parents": np.array(d["parents"], np.int64)}
    if "levels" in d:
        out["levels"] = np.array(d["levels"], np.int64)
    return out
