"""The grown tree record and the whole-tree graph: HBL branches plus colonized twigs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.model import HBL, Level

from .sca import Colonized


@dataclass(frozen=True, eq=False)
class Leaves:
    """Leaf cards: one quad per leaf, its stem at ``centres - axes * sizes / 2``."""

    centres: np.ndarray
    """(K, 3) float64, metres, world frame: card centres."""
    normals: np.ndarray
    """(K, 3) float64: unit facing direction of each card."""
    axes: np.ndarray
    """(K, 3) float64: unit direction from stem to tip, perpendicular to ``normals``."""
    sizes: np.ndarray
    """(K,) float64, metres: card length (its width is half of it)."""
    lobe: np.ndarray
    """(K,) int64: the lobe each leaf grew in."""


@dataclass(frozen=True, eq=False)
class GrownTree:
    """A whole tree as one graph (parents first), with radii and leaves."""

    positions: np.ndarray
    """(N, 3) float64, metres, world frame (Z up)."""
    parents: np.ndarray
    """(N,) int64: parent node (< own index), -1 for the root."""
    radii: np.ndarray
    """(N,) float64, metres: pipe-model radius of each node."""
    levels: np.ndarray
    """(N,) uint8: Level of the node (MAIN, SECONDARY, TWIG)."""
    lobe: np.ndarray
    """(N,) int64: lobe of a twig node, -1 for HBL branch nodes."""
    leaves: Leaves
    step: float
    """The growth radius D used (metres)."""
    iterations: int
    """Colonization iterations run."""

    @property
    def twig_count(self) -> int:
        """Number of twig nodes grown (not counting buds)."""
        return int((self.levels == Level.TWIG).sum())


@dataclass(frozen=True, eq=False)
class BranchGraph:
    """The HBL's branches as one node graph."""

    positions: np.ndarray
    """(N, 3) float64."""
    parents: np.ndarray
    """(N,) int64."""
    radii: np.ndarray
    """(N,) float64: the HBL's radius at each vertex."""
    levels: np.ndarray
    """(N,) uint8."""
    vertex_node: list[np.ndarray]
    """Per branch, (V,) int64: the node of each of its vertices."""


def branch_graph(hbl: HBL) -> BranchGraph:
    """Flatten the HBL's branches; a child's first vertex merges into its fork when it coincides."""
    if not hbl.branches:
        raise InputError("HBL: it has no branches, so there is nothing to grow twigs from")
    pos, par, rad, lev, vertex_node = [], [], [], [], []
    count = 0
    for b in hbl.branches:
        fork = int(vertex_node[b.parent][b.parent_vertex]) if b.parent >= 0 else -1
        merged = fork >= 0 and np.linalg.norm(
            b.points[0] - hbl.branches[b.parent].points[b.parent_vertex]) < 1e-9
        first = 1 if merged else 0
        ids = count + np.arange(len(b.points) - first)
        vertex_node.append(np.r_[fork, ids] if merged else ids)
        par.append(np.r_[fork, ids[:-1]])
        pos.append(b.points[first:])
        rad.append(b.radii[first:])
        lev.append(np.full(len(ids), int(b.level), np.uint8))
        count += len(ids)
    return BranchGraph(np.concatenate(pos), np.concatenate(par).astype(np.int64), np.concatenate(rad),
                       np.concatenate(lev), vertex_node)


def buds(hbl: HBL, graph: BranchGraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per lobe: bud node (L,), bud position (L, 3) and heading V_s (L, 3) (unit).

    The bud is the terminal vertex of the lobe's secondary branch and V_s that branch's tangent
    there. A lobe without a branch buds from the branch vertex nearest its centre, heading to it.
    """
    node, pos, head = [], [], []
    for lb in hbl.lobes:
        if lb.branch >= 0:
            pts = hbl.branches[lb.branch].points
            n = int(graph.vertex_node[lb.branch][-1])
            h = pts[-1] - pts[-2]
        else:
            n = int(np.argmin(np.linalg.norm(graph.positions - lb.centre, axis=1)))
            h = lb.centre - graph.positions[n]
        norm = np.linalg.norm(h)
        node.append(n)
        pos.append(graph.positions[n])
        head.append(h / norm if norm > 1e-12 else np.array([0.0, 0.0, 1.0]))
    return np.array(node, np.int64), np.array(pos).reshape(-1, 3), np.array(head).reshape(-1, 3)


def join(graph: BranchGraph, bud_nodes: np.ndarray, col: Colonized) -> tuple[np.ndarray, ...]:
    """Append the colonized twigs to the branch graph: positions, parents, levels, lobe (per node)."""
    n0, nb = len(graph.positions), len(bud_nodes)
    grown = np.arange(nb, len(col.positions))
    new_id = np.full(len(col.positions), -1, np.int64)
    new_id[:nb] = bud_nodes
    new_id[nb:] = n0 + np.arange(len(grown))
    positions = np.concatenate([graph.positions, col.positions[grown]])
    parents = np.concatenate([graph.parents, new_id[col.parents[grown]]])
    levels = np.concatenate([graph.levels, np.full(len(grown), int(Level.TWIG), np.uint8)])
    lobe = np.concatenate([np.full(n0, -1, np.int64), col.lobe[grown]])
    return positions, parents, levels, lobe
