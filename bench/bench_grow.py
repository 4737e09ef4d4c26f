"""Growth and meshing speed: a 50-lobe demo tree (VRTree section 3.5 pipeline).

Targets (issue 5): >= 20,000 twig nodes grown in < 1 s; >= 1M triangles meshed in < 2 s.
Baselines measured in the same run: a per-lobe loop of the same colonization (one lobe at a time,
the obvious way to write it), and a per-chain loop of the same tube sweep.
"""

from __future__ import annotations

import time

import numpy as np

from bench.harness import Row, median_time

SEED = 3
DENSITY = 2.1
"""Twig density: 2.1 keeps the workload above 20,000 twig nodes (2.0 gave 19,803 once twigs stopped
spilling out of their hulls, docs/growth.md)."""
SIDES = 20


def _setup():
    from arboretum_server.grow.demo import demo_hbl
    from arboretum_server.grow.options import GrowOptions

    return demo_hbl(np.random.default_rng(SEED), 50), GrowOptions(density=DENSITY)


def _per_lobe(hbl, opts):
    """Baseline: the same grow_tree, run lobe by lobe (HBL restricted to one lobe each time)."""
    from arboretum_library.model import HBL
    from arboretum_server.grow.attraction import default_step
    from arboretum_server.grow.tree import grow_tree

    step = default_step(hbl.lobes)
    o = type(opts)(density=opts.density, step=step)
    for lb in hbl.lobes:
        grow_tree(HBL(hbl.root, hbl.branches, (lb,)), o, np.random.default_rng(0))


def _per_chain_sweep(tree, sides):
    """Baseline: the same sweep called chain by chain."""
    from arboretum_server.mesh.chains import Chains, split_chains
    from arboretum_server.mesh.tubes import sweep

    ch = split_chains(tree.parents, tree.radii)
    for c in range(min(len(ch.starts) - 1, 2000)):
        a, b = ch.starts[c], ch.starts[c + 1]
        one = Chains(ch.nodes[a:b], np.array([0, b - a]), np.zeros(b - a, np.int64), ch.radius_node[a:b])
        sweep(tree.positions, tree.radii, one, sides)
    return min(len(ch.starts) - 1, 2000) / max(len(ch.starts) - 1, 1)


def _cpu_seconds(fn, runs: int = 3) -> float:
    """Median CPU time of ``fn()`` for this process (what the wall time would be on an idle core)."""
    times = []
    for _ in range(runs):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return float(np.median(times))


def run() -> list[Row]:
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.lod import LodOptions
    from arboretum_server.mesh.scene import tree_mesh

    hbl, opts = _setup()
    tree = grow_tree(hbl, opts, np.random.default_rng(0))
    t_grow = median_time(lambda: grow_tree(hbl, opts, np.random.default_rng(0)), runs=5)
    cpu_grow = _cpu_seconds(lambda: grow_tree(hbl, opts, np.random.default_rng(0)))
    t_lobe = median_time(lambda: _per_lobe(hbl, opts), runs=1, warmup=0)
    lod = LodOptions(sides=SIDES)
    mesh = tree_mesh(tree, lod)
    t_mesh = median_time(lambda: tree_mesh(tree, lod), runs=5)
    cpu_mesh = _cpu_seconds(lambda: tree_mesh(tree, lod))
    frac = _per_chain_sweep(tree, SIDES)
    t_chain = median_time(lambda: _per_chain_sweep(tree, SIDES), runs=1, warmup=0) / frac
    return [
        Row(f"grow 50 lobes -> {tree.twig_count} twig nodes", t_grow, "s", 1.0, 5,
            "same growth, lobe by lobe", t_grow / t_lobe,
            extra={"twig_nodes": tree.twig_count, "leaves": int(len(tree.leaves.sizes)),
                   "iterations": tree.iterations, "density": DENSITY, "cpu_s": cpu_grow}),
        Row(f"mesh tree -> {mesh.triangles} triangles ({SIDES} sides)", t_mesh, "s", 2.0, 5,
            "same sweep, chain by chain (extrapolated)", t_mesh / t_chain,
            extra={"triangles": mesh.triangles, "bark_triangles": int(len(mesh.bark.faces)),
                   "cpu_s": cpu_mesh}),
    ]
