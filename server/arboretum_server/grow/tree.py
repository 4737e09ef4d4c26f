"""grow_tree: an HBL in, a whole grown tree (skeleton, radii, leaves) out."""

from __future__ import annotations

import dataclasses

import numpy as np

from arboretum_library.model import HBL
from arboretum_library.progress import ProgressFn, no_progress

from .attraction import attraction_points, default_step
from .leaves import place_leaves
from .options import GrowOptions
from .radii import lobe_twig_radii, pipe_radii
from .sca import colonize
from .skeleton import BranchGraph, GrownTree, Leaves, branch_graph, buds, join


def grow_tree(hbl: HBL, opts: GrowOptions, rng: np.random.Generator,
              progress: ProgressFn = no_progress) -> GrownTree:
    """Colonize every lobe of ``hbl`` from its bud, then give the whole tree radii and leaves.

    Same ``rng`` state, same tree. Radii follow ``opts.branch_radii`` (see ``_radii``). The tree grows in
    a frame whose origin is the HBL root rounded to whole metres (``growth_origin``), so a tree moved by
    whole metres (to UTM or geocentric coordinates, say) has the same coordinates in that frame and grows
    as before, only translated (up to the float64 rounding of its input at the new magnitude, ~1e-9 m at
    UTM). Moved by a fraction of a metre, it stands elsewhere in that frame, and its twigs and leaves may
    differ: the cell grid, the hull sampling and float rounding depend on where it stands.
    """
    origin = growth_origin(hbl)
    if origin.any():
        tree = grow_tree(hbl.map_positions(lambda a: a - origin), opts, rng, progress)
        lv = tree.leaves
        leaves = Leaves(lv.centres + origin, lv.normals, lv.axes, lv.sizes, lv.lobe)
        return dataclasses.replace(tree, positions=tree.positions + origin, leaves=leaves)
    graph = branch_graph(hbl)
    step = opts.step if opts.step is not None else default_step(hbl.lobes)
    positions, parents, levels, lobe = graph.positions, graph.parents, graph.levels, None
    leaves, iterations = _no_leaves(), 0
    if len(hbl.lobes):
        bud_node, bud_pos, heading = buds(hbl, graph)
        att = attraction_points(hbl.lobes, opts, step, rng)
        col = colonize(att, bud_pos, np.arange(len(hbl.lobes)), heading, opts, step, progress)
        positions, parents, levels, lobe = join(graph, bud_node, col)
        iterations = col.iterations
        leaves = place_leaves(positions, parents, lobe, hbl.lobes, att.index, opts, step, rng)
    if lobe is None:
        lobe = np.full(len(positions), -1, np.int64)
    radii = _radii(hbl, graph, parents, lobe, opts, step)
    progress(1, 1, f"grown {int((lobe >= 0).sum())} twig nodes, {len(leaves.sizes)} leaves")
    return GrownTree(positions, parents, radii, levels, lobe, leaves, float(step), iterations)


def growth_origin(hbl: HBL) -> np.ndarray:
    """(3,) float64, metres: the origin of the frame a tree grows in, its root rounded to whole metres.

    (0, 0, 0) for a tree rooted within half a metre of the world origin (it grows where it stands, bit
    for bit as before). Growth depends on absolute coordinates through its cell grid, its hull sampling
    and float rounding; relative to this origin it does not, and subtracting a whole number of metres
    from coordinates near it is exact.
    """
    return np.round(np.asarray(hbl.root, np.float64)) + 0.0


def _radii(hbl: HBL, graph: BranchGraph, parents: np.ndarray, lobe: np.ndarray, opts: GrowOptions,
           step: float) -> np.ndarray:
    """Radii (N,) of the whole tree.

    "hbl" mode: HBL branch vertices keep their radii (the tree's scale, whatever the twig density);
    each lobe's twigs get pipe-model radii fitted under their bud (``lobe_twig_radii``). "pipe" mode:
    the pipe model from every tip to the root (twig tips at ``tip_radius``, HBL tips at their radius).
    """
    tip = opts.tip_radius if opts.tip_radius is not None else 0.08 * step
    mode = opts.branch_radii
    if mode == "auto":
        mode = "hbl" if hbl_radii_consistent(hbl) else "pipe"
    if mode == "hbl":
        return lobe_twig_radii(parents, lobe, graph.radii, tip, opts.min_twig_radius * tip, opts.pipe_exponent)
    tips = np.full(len(parents), tip)
    tips[: len(graph.radii)] = np.maximum(graph.radii, tip)
    return pipe_radii(parents, tips, opts.pipe_exponent)


def hbl_radii_consistent(hbl: HBL) -> bool:
    """True when the HBL's radii can be the tree's scale: not all equal, never growing towards a
    branch's tip, and no branch thicker at its first vertex than its parent at the joint."""
    rad = np.concatenate([b.radii for b in hbl.branches])
    if rad.max() - rad.min() <= 1e-9 * rad.max():
        return False
    for b in hbl.branches:
        if (np.diff(b.radii) > 1e-12 * b.radii[0]).any():
            return False
        if b.parent >= 0 and b.radii[0] > hbl.branches[b.parent].radii[b.parent_vertex] * (1 + 1e-9):
            return False
    return True


def _no_leaves() -> Leaves:
    z3, z0 = np.zeros((0, 3)), np.zeros(0)
    return Leaves(z3, z3, z3, z0, z0.astype(np.int64))
