"""grow_tree: an HBL in, a whole grown tree (skeleton, radii, leaves) out."""

from __future__ import annotations

import numpy as np

from arboretum_library.model import HBL
from arboretum_library.progress import ProgressFn, no_progress

from .attraction import attraction_points, default_step
from .leaves import place_leaves
from .options import GrowOptions
from .radii import pipe_radii
from .sca import colonize
from .skeleton import GrownTree, Leaves, branch_graph, buds, join


def grow_tree(hbl: HBL, opts: GrowOptions, rng: np.random.Generator,
              progress: ProgressFn = no_progress) -> GrownTree:
    """Colonize every lobe of ``hbl`` from its bud, then give the whole tree radii and leaves.

    Same ``rng`` state, same tree. Tips of twigs get ``tip_radius``; tips of HBL branches keep
    their HBL radius; every other radius follows the pipe model.
    """
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
    tip = opts.tip_radius if opts.tip_radius is not None else 0.08 * step
    tips = np.full(len(positions), tip)
    tips[: len(graph.radii)] = np.maximum(graph.radii, tip)
    radii = pipe_radii(parents, tips, opts.pipe_exponent)
    progress(1, 1, f"grown {int((lobe >= 0).sum())} twig nodes, {len(leaves.sizes)} leaves")
    return GrownTree(positions, parents, radii, levels, lobe, leaves, float(step), iterations)


def _no_leaves() -> Leaves:
    z3, z0 = np.zeros((0, 3)), np.zeros(0)
    return Leaves(z3, z3, z3, z0, z0.astype(np.int64))
