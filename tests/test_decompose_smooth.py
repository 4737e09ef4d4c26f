"""Branch smoothing (decompose/smooth.py) and the bare-trunk relabelling: unit and end-to-end checks."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.descriptors import polyline_curvature
from arboretum_library.model import LEAF, Level
from arboretum_server.decompose import refine
from arboretum_server.decompose.evaluate import connected, mean_turning, turning_angles
from arboretum_server.decompose.graph import knn_graph, shortest_paths
from arboretum_server.decompose.grid import BoxGrid
from arboretum_server.decompose.merge import BranchSet, add_branch
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import bare_trunk, decompose
from arboretum_server.decompose.secondary import branch_paths
from arboretum_server.decompose.smooth import LIMIT, smooth_branchset, smooth_polylines
from arboretum_server.decompose.toytree import toy_scan, toy_truth

STRAIGHT_RAD = 0.35
"""descriptors.Thresholds.straight_rad: below this total turning a main branch is 'straight'."""


def _zigzag(n: int = 40, amp: float = 0.004, step: float = 0.01) -> np.ndarray:
    z = np.arange(n) * step
    x = np.where(np.arange(n) % 2 == 0, amp, -amp)
    x[0] = x[-1] = 0.0
    return np.c_[x, np.zeros(n), z]


def test_smoothing_removes_zigzag_keeps_ends_and_limit():
    line = _zigzag()
    (out,) = smooth_polylines([line])
    assert out.shape == line.shape
    assert np.array_equal(out[0], line[0]) and np.array_equal(out[-1], line[-1])
    assert np.linalg.norm(out - line, axis=1).max() <= LIMIT + 1e-12
    assert turning_angles(line).mean() > 0.7
    assert turning_angles(out).mean() < 0.05
    (capped,) = smooth_polylines([line], limit=0.001)
    assert np.linalg.norm(capped - line, axis=1).max() <= 0.001 + 1e-12


def test_smoothing_keeps_children_exactly_on_their_parents():
    kept = BranchSet()
    trunk = _zigzag(40)
    add_branch(kept, trunk, -1, -1)
    side = trunk[12] + np.c_[np.arange(15) * 0.01, np.where(np.arange(15) % 2, 0.003, -0.003), np.zeros(15)]
    side[0] = trunk[12]
    add_branch(kept, side, 0, 12)
    twig = side[7] + np.c_[np.zeros(8), np.arange(8) * 0.01, np.arange(8) * 0.004]
    add_branch(kept, twig, 1, 7)
    out = smooth_branchset(kept)
    assert [len(s) for s in out.segments] == [40, 15, 8] and out.parents == [0 - 1, 0, 1]
    for b in (1, 2):
        p, pv = out.parents[b], out.parent_vertex[b]
        assert np.linalg.norm(out.segments[b][0] - out.segments[p][pv]) <= 1e-9
    # full paths run root -> tip through the smoothed parents
    assert np.allclose(out.full[2][0], out.segments[0][0]) and np.allclose(out.full[2][-1], out.segments[2][-1])
    assert np.allclose(out.full[2][12], out.segments[0][12])
    assert turning_angles(out.segments[0]).mean() < 0.5 * turning_angles(trunk).mean()


def test_straight_scanned_branch_reads_straight(rng):
    """A straight inclined cylinder scanned with noise: its graph path is not straight, the smoothed one is."""
    n = 3000
    t = rng.uniform(0, 0.6, n)
    a = rng.uniform(0, 2 * np.pi, n)
    axis = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
    u = np.cross(axis, [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    r = 0.012 + rng.normal(0, 0.002, n)
    pts = t[:, None] * axis + r[:, None] * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * v)
    pts = np.vstack([[0.0, 0.0, 0.0], pts, 0.6 * axis])
    g = knn_graph(pts, 5, 0.05)
    _, pred = shortest_paths(g.adjacency, 0)
    (path,) = branch_paths([len(pts) - 1], pred, pts, BoxGrid(pts, 0.02 / 1.5), 0.01)
    (smooth,) = smooth_polylines([path])
    assert polyline_curvature(smooth) < STRAIGHT_RAD
    assert turning_angles(smooth).mean() < 0.5 * turning_angles(path).mean()


@pytest.fixture(scope="module")
def toy():
    pts, lab = toy_scan(toy_truth(), n=12000, seed=1)
    return pts, lab, decompose(pts, DecomposeOptions())


def test_decomposed_branches_are_smooth_and_connected(toy):
    """Before smoothing this scan's main branches turned 0.34 rad per vertex, secondaries 0.50."""
    _, _, d = toy
    assert mean_turning(d.hbl, Level.MAIN) < 0.12
    assert mean_turning(d.hbl, Level.SECONDARY) < 0.12
    assert connected(d.hbl)
    for b in d.hbl.branches[1:]:
        assert np.linalg.norm(b.points[0] - d.hbl.branches[b.parent].points[b.parent_vertex]) <= 1e-9


def test_refined_secondaries_are_smooth_and_connected(toy):
    _, _, d = toy
    m = refine.merge_lobes(d, [1, 2])
    new = m.hbl.branches[-1]
    assert new.level == Level.SECONDARY and len(m.hbl.lobes) == len(d.hbl.lobes) - 1
    # (this merged lobe's smoothed branch would enter a foreign lobe: its unsmoothed path is kept)
    assert mean_turning(m.hbl, Level.SECONDARY) < 0.12 and connected(m.hbl)
    s = refine.split_lobe(d, 4, [d.hbl.lobes[4].points[:2], d.hbl.lobes[4].points[-2:]])
    assert len(s.hbl.lobes) == len(d.hbl.lobes) + 1 and connected(s.hbl)
    assert mean_turning(s.hbl, Level.SECONDARY) < 0.12


def test_bare_trunk_points_become_wood(toy):
    pts, _, d = toy
    bare = bare_trunk(d.points, d.mains)
    z = d.points[bare, 2]
    forks = min(pv for p, pv in zip(d.mains.parents, d.mains.parent_vertex) if p == 0)
    assert bare.any() and z.max() <= d.mains.segments[0][forks, 2] + 0.02
    assert not (d.labels[bare] == LEAF).any()
    assert not np.isin(np.flatnonzero(bare), np.concatenate([lb.members for lb in d.lobes])).any()
