"""Ground truth of a synthetic tree: one record for every generator (guiding vectors, harmonic model).

A ``TreeTruth`` is a skeleton graph (nodes with positions and radii, a parent per node, branch ids and
branch orders) plus leaf cards and provenance. The virtual scanner samples point clouds from it, and
evaluations compare reconstructions against it (``branch_polylines``).

Conventions: right-handed, Z up, metres, float64; int32 indices. Nodes are in topological order (a
node's parent has a smaller index), so node 0 is the one root (the trunk base). A *branch* is a chain of
nodes sharing one ``branch_id``; its first node's parent lies on another branch (or is -1 for the trunk).

Leaf cards: leaf ``j`` is a flat card centred on ``leaf_positions[j]``. Its unit quaternion
``leaf_wxyz[j]`` rotates the card frame to the world: card +X runs along the blade (petiole to tip), card
+Y across it, card +Z is the blade normal. The card spans ``leaf_sizes[j]`` along X and
``leaf_sizes[j] * LEAF_WIDTH_RATIO`` along Y; the blade is the ellipse inscribed in the card.

Files: ``save_truth`` / ``load_truth`` are ``codec.save_record`` / ``load_record`` with compression:
one .npz holding the arrays and a ``__meta__`` JSON entry (kind ``TreeTruth``), written to a temporary
file and renamed, so Ctrl-C never leaves a broken file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .codec import load_record, save_record
from .errors import ValidationError
from .geometry import quat_to_matrix
from .model import frozen_array

F64 = NDArray[np.float64]
I32 = NDArray[np.int32]

LEAF_WIDTH_RATIO = 0.5
"""Width of a leaf card (card Y extent) as a fraction of its size (card X extent)."""


def _empty(shape: tuple[int, ...], dtype: type = np.float64):
    return field(default_factory=lambda: np.zeros(shape, dtype))


@dataclass(frozen=True, eq=False)
class TreeTruth:
    """The ground truth of one synthetic tree (skeleton graph, leaves, provenance)."""

    positions: F64
    """(N, 3) float64, metres, world (Z up): skeleton node positions. N >= 2; node 0 is the root."""
    radii: F64
    """(N,) float64, metres, > 0: branch radius at each node (pipe model from the tips)."""
    parent: I32
    """(N,) int32: parent node index (< own index), -1 for the root only."""
    branch_id: I32
    """(N,) int32, >= 0: the branch each node belongs to; each branch is one chain of nodes."""
    branch_order: I32
    """(N,) int32, >= 0: 0 for the trunk, 1 for its branches, ...; constant along a branch."""
    leaf_positions: F64 = _empty((0, 3))
    """(L, 3) float64, metres, world: leaf card centres."""
    leaf_wxyz: F64 = _empty((0, 4))
    """(L, 4) float64: unit quaternions (w, x, y, z) rotating the card frame to the world."""
    leaf_sizes: F64 = _empty((0,))
    """(L,) float64, metres, > 0: card length along card X (width is LEAF_WIDTH_RATIO of it)."""
    leaf_node: I32 = _empty((0,), np.int32)
    """(L,) int32: the skeleton node each leaf hangs on. Empty with L > 0 means: the nearest node."""
    model: str = "unknown"
    """Generator name: 'guiding' or 'harmonic'."""
    species: str = "unknown"
    """Species or preset name (lower case)."""
    seed: int = 0
    """The seed of the numpy Generator that grew the tree."""
    parameters: Mapping[str, Any] = field(default_factory=dict)
    """Every generator parameter (JSON-serialisable), so the tree can be grown again."""

    def __post_init__(self) -> None:
        pos = frozen_array(self, "positions", self.positions, np.float64, (None, 3))
        n = len(pos)
        if n < 2:
            raise ValidationError(f"TreeTruth.positions: a skeleton needs >= 2 nodes, got {n}")
        rad = frozen_array(self, "radii", self.radii, np.float64, (n,))
        if (rad <= 0).any():
            raise ValidationError(
                f"TreeTruth.radii: {int((rad <= 0).sum())} radius(es) are not > 0"
            )
        parent = frozen_array(self, "parent", self.parent, np.int32, (n,))
        _check_topology(parent)
        bid = frozen_array(self, "branch_id", self.branch_id, np.int32, (n,))
        order = frozen_array(self, "branch_order", self.branch_order, np.int32, (n,))
        _check_branches(parent, bid, order)
        self._validate_leaves(n)
        try:
            params = json.loads(json.dumps(dict(self.parameters)))
        except (TypeError, ValueError) as exc:
            raise ValidationError(f"TreeTruth.parameters: not JSON-serialisable ({exc})") from None
        object.__setattr__(self, "parameters", params)
        object.__setattr__(self, "seed", int(self.seed))

    def _validate_leaves(self, n: int) -> None:
        lp = frozen_array(self, "leaf_positions", self.leaf_positions, np.float64, (None, 3))
        m = len(lp)
        q = frozen_array(self, "leaf_wxyz", self.leaf_wxyz, np.float64, (m, 4))
        if m and np.abs(np.linalg.norm(q, axis=1) - 1.0).max() > 1e-6:
            raise ValidationError(
                "TreeTruth.leaf_wxyz: quaternions must have unit length (within 1e-6)"
            )
        sizes = frozen_array(self, "leaf_sizes", self.leaf_sizes, np.float64, (m,))
        if (sizes <= 0).any():
            raise ValidationError(
                f"TreeTruth.leaf_sizes: {int((sizes <= 0).sum())} size(s) are not > 0"
            )
        node = np.asarray(self.leaf_node, dtype=np.int32).reshape(-1)
        if m and node.size == 0:
            node = _nearest_nodes(lp, self.positions)
        node = frozen_array(self, "leaf_node", node, np.int32, (m,))
        if m and (node.min() < 0 or node.max() >= n):
            raise ValidationError(f"TreeTruth.leaf_node: indices must lie in 0..{n - 1}")

    @property
    def node_count(self) -> int:
        return len(self.positions)

    @property
    def leaf_count(self) -> int:
        return len(self.leaf_positions)

    @property
    def branch_count(self) -> int:
        return len(np.unique(self.branch_id))


def _check_topology(parent: np.ndarray) -> None:
    idx = np.arange(len(parent))
    roots = np.flatnonzero(parent < 0)
    if roots.tolist() != [0] or parent[0] != -1:
        raise ValidationError(
            f"TreeTruth.parent: need exactly one root (-1) at node 0, got roots {roots[:5].tolist()}"
        )
    bad = np.flatnonzero(parent[1:] >= idx[1:]) + 1
    if bad.size:
        raise ValidationError(
            f"TreeTruth.parent: node {int(bad[0])} has parent {int(parent[bad[0]])}; parents must come first"
        )


def _check_branches(parent: np.ndarray, bid: np.ndarray, order: np.ndarray) -> None:
    if bid.min() < 0 or order.min() < 0:
        raise ValidationError("TreeTruth.branch_id/branch_order: values must be >= 0")
    p = np.maximum(parent, 0)
    first = (parent < 0) | (bid[p] != bid)
    starts = np.bincount(bid[first], minlength=int(bid.max()) + 1)
    used = np.bincount(bid, minlength=len(starts)) > 0
    if (starts[used] != 1).any():
        b = int(np.flatnonzero(used & (starts != 1))[0])
        raise ValidationError(
            f"TreeTruth.branch_id: branch {b} must be one chain with one first node"
        )
    cont = np.flatnonzero(~first)
    if (np.bincount(parent[cont], minlength=len(parent)) > 1).any():
        raise ValidationError(
            "TreeTruth.branch_id: a node continues into two children of its own branch"
        )
    if (order[cont] != order[parent[cont]]).any():
        raise ValidationError("TreeTruth.branch_order: must be constant along a branch")
    kids = np.flatnonzero(first & (parent >= 0))
    if (order[kids] < order[parent[kids]]).any():
        raise ValidationError(
            "TreeTruth.branch_order: a branch cannot have a lower order than its parent"
        )


def _nearest_nodes(q: np.ndarray, positions: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """Index (M,) of the nearest of ``positions`` (N, 3) to each ``q`` (M, 3), brute force in chunks."""
    q = np.asarray(q, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    out = np.zeros(len(q), np.int32)
    step = max(1, chunk * 1024 // max(len(p), 1))
    for s in range(0, len(q), step):
        d = ((q[s : s + step, None, :] - p[None]) ** 2).sum(axis=2)
        out[s : s + step] = d.argmin(axis=1)
    return out


def pipe_model_radii(parent: np.ndarray, tip_radius: float, exponent: float = 2.0) -> np.ndarray:
    """Radii (N,) by the pipe model from the tips: ``r_parent**e = sum(r_child**e)``.

    Every tip (a node without children) gets ``tip_radius``; ``exponent`` e = 2 is da Vinci's rule
    (cross-section areas add up), 2.5-3 gives thinner trunks. ``parent`` (N,) must be in topological
    order (parents first).
    """
    parent = np.asarray(parent, dtype=np.int64)
    acc = np.zeros(len(parent))
    has_child = np.zeros(len(parent), bool)
    has_child[parent[parent >= 0]] = True
    acc[~has_child] = tip_radius**exponent
    par = parent.tolist()
    vals = acc.tolist()
    for i in range(len(par) - 1, 0, -1):
        vals[par[i]] += vals[i]
    return np.asarray(vals) ** (1.0 / exponent)


def branch_polylines(truth: TreeTruth) -> list[np.ndarray]:
    """Node indices of each branch, in ascending branch id: the attachment node first, then the tip.

    A branch's list starts with the node it grows from on its parent branch (none for the trunk) and
    follows its own chain to its tip, so ``truth.positions[idx]`` is a polyline from the fork outward.
    """
    bid, parent = truth.branch_id, truth.parent
    order = np.argsort(bid, kind="stable")  # topological order kept inside each branch
    ids, starts = np.unique(bid[order], return_index=True)
    chains = np.split(order, starts[1:])
    out = []
    for chain in chains:
        head = int(parent[chain[0]])
        out.append(
            np.concatenate([[head], chain]).astype(np.int32)
            if head >= 0
            else chain.astype(np.int32)
        )
    return out


def polyline_length(truth: TreeTruth, nodes: np.ndarray) -> float:
    """Arc length in metres of the polyline through ``truth.positions[nodes]``."""
    pts = truth.positions[np.asarray(nodes)]
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def leaf_card_corners(truth: TreeTruth) -> np.ndarray:
    """(L, 4, 3) world corners of each leaf card, counter-clockwise seen from card +Z."""
    half = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    out = np.zeros((truth.leaf_count, 4, 3))
    for j in range(truth.leaf_count):
        R = quat_to_matrix(truth.leaf_wxyz[j])
        s = truth.leaf_sizes[j]
        local = half * [s, s * LEAF_WIDTH_RATIO]
        out[j] = truth.leaf_positions[j] + local @ R[:, :2].T
    return out


def save_truth(path: str | os.PathLike, truth: TreeTruth) -> Path:
    """Write ``truth`` to ``path`` atomically as a compressed record file (``codec.save_record``)."""
    return save_record(path, truth, compress=True)


def load_truth(path: str | os.PathLike) -> TreeTruth:
    """Read a ``TreeTruth`` written by ``save_truth``; ``InputError`` if missing, foreign or broken."""
    return load_record(path, TreeTruth)
