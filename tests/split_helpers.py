"""Shared by the split tests: the leaf-on harmonic pine's decomposition (made once per test process) and
one-point strokes drawn as the bench's ``_twenty_strokes`` draws them."""

from __future__ import annotations

from functools import cache

import numpy as np


@cache
def leaf_on_pine():
    """The decomposition of the harmonic pine's leaf-on toy scan (seed 1, 40,000 points). Refinement
    operations are pure (they return a new decomposition), so the tests share this one."""
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose
    from arboretum_server.decompose.report import CASES, grow_truth
    from arboretum_server.decompose.toytree import toy_scan

    truth = grow_truth("harmonic", "pine", 1)
    pts, _ = toy_scan(truth, n=40000, noise=0.002 * float(np.ptp(truth.positions[:, 2])), seed=1,
                      **CASES["leaf-on"])
    return decompose(pts, DecomposeOptions(species="pine"))


def bench_strokes(d, j: int, k: int, first_seed: int = 100) -> list[np.ndarray]:
    """``k`` one-point strokes (output frame) as the bench's ``_twenty_strokes`` draws them: the lobe's points
    nearest a k-means++ clustering of it (seeds ``first_seed`` to ``first_seed + 3``, the bench's 100-103), the
    first set that gives every piece 4 points."""
    from scipy.cluster.vq import kmeans2
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.refine import MIN_LOBE_POINTS, from_output, stroke_parts

    m = d.lobes[j].members
    for seed in range(first_seed, first_seed + 4):
        pick = m[cKDTree(d.points[m]).query(kmeans2(d.points[m], k, seed=seed, minit="++")[0])[1]]
        strokes = [d.to_output(d.points[p])[None] for p in pick]
        if len(set(pick.tolist())) == k:
            owner = stroke_parts(d.points[m], [from_output(d, s) for s in strokes], j, 1.0)
            if np.bincount(owner, minlength=k).min() >= MIN_LOBE_POINTS:
                return strokes
    raise AssertionError(f"no stroke set splits lobe {j} in {k}")
