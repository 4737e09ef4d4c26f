"""The refinement fast paths of session 21 give the answers of the plain code they replace: the routes' lobes
entered counted in one pass (``tunnel.lobes_entered``), one KD-tree per point array (``secondary.cloud_tree``)
and the displacement limits' median read off the sorted distances (``smooth.vertex_limits``)."""

from __future__ import annotations

import numpy as np


def _alpha_lobes(rng, n=6):
    """``n`` lobes whose hulls are alpha shapes of 300 points in a bent slab (many faces, several per cell)."""
    from arboretum_server.decompose.lobes import lobe_hull
    from arboretum_server.decompose.state import LobeState

    out = []
    for _ in range(n):
        c = rng.uniform(0, 0.6, 3)
        p = c + rng.normal(0, [0.08, 0.05, 0.03], (300, 3))
        p[:, 2] += 2.0 * (p[:, 0] - c[0]) ** 2
        v, f, _ = lobe_hull(p, 0.04)
        out.append(LobeState(np.arange(3), c, v, f, True, np.zeros((2, 3)), 0, 0))
    return out


def test_lobes_entered_counts_what_enters_gives_pair_by_pair(rng):
    from arboretum_server.decompose.merge import sample_polylines
    from arboretum_server.decompose.tunnel import enters, lobes_entered

    lobes = _alpha_lobes(rng)
    woods = [sample_polylines([np.linspace(rng.uniform(-0.1, 0.7, 3), rng.uniform(-0.1, 0.7, 3), 5)], 0.0025)
             for _ in range(200)]
    which = [0, 1, 2, 3, 5]
    want = [sum(enters(lobes[k], w) for k in which) for w in woods]
    got = lobes_entered(lobes, which, woods)
    assert got.tolist() == want and min(want) == 0 and max(want) >= 2
    assert lobes_entered(lobes, which, []).shape == (0,)


def test_one_kd_tree_per_point_array_answers_as_a_new_one(rng):
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.secondary import cloud_tree

    pts = rng.uniform(0, 1, (5000, 3))
    tree = cloud_tree(pts)
    assert cloud_tree(pts) is tree and cloud_tree(pts.copy()) is not tree
    q = rng.uniform(0, 1, (300, 3))
    assert all(np.array_equal(a, b) for a, b in zip(tree.query(q, k=8), cKDTree(pts).query(q, k=8)))


def test_vertex_limits_are_the_median_of_eight_spacings(rng):
    from scipy.spatial import cKDTree

    from arboretum_server.decompose.smooth import LIMIT, LIMIT_MIN, LOCAL_SPACINGS, vertex_limits

    tree = cKDTree(rng.uniform(0, 0.06, (3000, 3)))
    segs = [rng.uniform(0, 0.06, (40, 3)), rng.uniform(0, 0.06, (7, 3))]
    d = tree.query(np.concatenate(segs), k=8)[0]
    want = np.clip(LOCAL_SPACINGS * np.median(d, axis=1), LIMIT_MIN, LIMIT)
    got = vertex_limits(segs, tree)
    assert np.array_equal(got, want) and ((LIMIT_MIN < got) & (got < LIMIT)).sum() > 20
