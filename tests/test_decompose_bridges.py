"""Bridging a kNN graph split into many components (full-resolution scans): each lonely component's
shortest edge to the rest, found among its points' own neighbours, is the brute-force one."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from arboretum_server.decompose import graph
from arboretum_server.decompose.graph import SMALL_COMPONENT, _nearest_pair, knn_graph


def _brute(points, inside, lab, c):
    out = np.flatnonzero(lab != c)
    d = np.linalg.norm(points[inside][:, None] - points[out][None], axis=2)
    r, k = np.unravel_index(int(np.argmin(d)), d.shape)
    return inside[r], out[k], d[r, k]


@pytest.mark.parametrize("size", [3, 40, 300, SMALL_COMPONENT])
def test_a_lonely_components_nearest_pair_is_the_brute_force_one(rng, size):
    # a dense blob (the component) among scattered clusters: its interior points' nearest neighbours
    # are all its own, so the search must widen past them without missing the true shortest edge
    blob = rng.normal(0, 0.01, (size, 3))
    others = rng.normal(0, 0.08, (1500, 3)) + [0.1, 0, 0]
    points = np.vstack([blob, others])
    lab = np.r_[np.zeros(size, int), 1 + rng.integers(0, 20, 1500)]
    inside = np.arange(size)
    a, b, w = _nearest_pair(points, cKDTree(points), inside, lab, 0)
    ea, eb, ew = _brute(points, inside, lab, 0)
    assert (a[0], b[0]) == (ea, eb) and w[0] == pytest.approx(ew, rel=1e-12)


def test_many_lonely_components_are_bridged_as_before(rng, monkeypatch):
    # 150 blobs of 30-200 points on a line, 4 cm apart: K = 5 neighbours never leave a blob
    centres = np.c_[np.arange(150) * 0.04, np.zeros(150), np.zeros(150)]
    pts = np.vstack([c + rng.normal(0, 0.003, (int(rng.integers(30, 200)), 3)) for c in centres])
    g = knn_graph(pts, 5, 0.05)
    assert g.components == 150 and g.bridges == 149
    assert connected_components(g.adjacency, directed=False)[0] == 1
    monkeypatch.setattr(graph, "SMALL_COMPONENT", 0)  # every component through a tree of the others
    ref = knn_graph(pts, 5, 0.05)
    assert (g.adjacency != ref.adjacency).nnz == 0
