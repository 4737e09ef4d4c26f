"""A piece apart under a tree with no ground (helper-155's rule, landed in session 23 by helper-159).

A clump of 1-3 % of the points 5-20 % of the height under scans 01, 06, 07 with no ground became their
root. A small piece apart under the tree is now left out (``detached``) unless it stands under the
trunk rising from the root found without it (``under``: a foot seen apart). That trunk's axis is fitted
above the root and carried down to the piece: measured at the root itself, the feet of trees leaning
10-30 degrees with their trunk unseen above the foot were left out (helper-156's review).
"""

import numpy as np
import pytest

from arboretum_server.decompose.trunkbase import detached, find_root, under
from arboretum_server.decompose.trunkbase_piece import _axis_at
from factories import layered_tree, prepared_root, real_scan


def _clump(pts: np.ndarray, share: float, below: float, side: float, seed: int = 11) -> np.ndarray:
    """``share`` of the points in a blob (sigma 1 % of the height) ``below`` of the height under the lowest
    point, ``side`` of it in x from the median of the lowest 1 %."""
    h, low = float(np.ptp(pts[:, 2])), pts[pts[:, 2] < np.percentile(pts[:, 2], 1)]
    centre = np.r_[np.median(low[:, :2], axis=0) + [side * h, 0.0], pts[:, 2].min() - below * h]
    return centre + np.random.default_rng(seed).normal(0, 0.01 * h, (int(share * len(pts)), 3))


@pytest.mark.parametrize("key, share, below, side", [("01", 0.02, 0.1, 0.05), ("01", 0.01, 0.2, 0.15),
                                                     ("06", 0.03, 0.05, 0.15), ("07", 0.02, 0.1, 0.05)])
def test_a_clump_apart_under_a_groundless_scan_is_left_out(key, share, below, side):
    # before: the root on the clump, 9-27 % of the height from the scan's own
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.preprocess import prepare

    pts, clean = real_scan(key)
    blob = _clump(pts, share, below, side)
    o = DecomposeOptions()
    p = prepare(np.r_[pts, blob], o, np.random.default_rng(o.seed))
    assert np.linalg.norm(p.root_scan - clean) < 0.01 * np.ptp(pts[:, 2])
    assert not np.isin(p.source_index, np.arange(len(pts), len(pts) + len(blob))).any()
    assert p.apart >= 0.9 * len(blob) * len(p.points) / (len(pts) + len(blob))  # counted as left out
    assert p.strays < p.apart  # and not as strays, whose note says "over a tenth of its height" away


def test_two_clumps_under_scan_01_are_both_left_out():
    # helper-147's "+2clumps_below": 1 % each, 12 and 15 % of the height under it; before 23 % off
    pts, clean = real_scan("01")
    two = np.r_[pts, _clump(pts, 0.01, 0.15, -0.1, 5), _clump(pts, 0.01, 0.12, 0.1, 6)]
    assert np.linalg.norm(prepared_root(two) - clean) < 0.01 * np.ptp(pts[:, 2])


def _cylinder(rng: np.random.Generator, z0: float, z1: float, r: float, n: int, lean: float = 0.0,
              half: bool = False) -> np.ndarray:
    """``n`` points on a trunk of radius ``r`` from ``z0`` to ``z1``, leaning ``lean`` degrees along x
    (``half``: one side seen only)."""
    z, a = rng.uniform(z0, z1, n), rng.uniform(np.pi / 2, 1.5 * np.pi, n) if half else rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(a) + np.tan(np.radians(lean)) * z, r * np.sin(a), z]


def _occluded(rng: np.random.Generator) -> np.ndarray:
    """helper-96's tree: a trunk foot seen from 0 to 0.5, the trunk from 2.7 to 8, a crown round 14."""
    v = rng.normal(size=(10400, 3))
    return np.r_[_cylinder(rng, 0.0, 0.5, 0.25, 100), _cylinder(rng, 2.7, 8.0, 0.22, 1500),
                 5 * v / np.linalg.norm(v, axis=1)[:, None] + [0, 0, 14]]


def test_a_trunk_foot_seen_apart_keeps_the_root():
    # guard (passed before too): the foot is apart, but under the trunk
    pts = _occluded(np.random.default_rng(1))
    assert detached(pts, pts[:, 2], find_root(pts))[:100].all()
    assert abs(prepared_root(pts)[2]) < 0.05


def test_a_few_points_apart_are_no_piece_to_leave_out():
    # guard: 9 points of scan 06's foot, half the scan occluded, lay 0.5 under the rest and 0.22 beside
    # the trunk above (helper-131's r06_occluded_half+ground): the root stays on them
    pts = _occluded(np.random.default_rng(1))
    pts = np.r_[pts[:9] + [0.5, 0.0, 0.0], pts[100:]]
    assert not detached(pts, pts[:, 2], find_root(pts)).any()


def test_the_same_foot_beside_the_trunk_is_left_out():
    # before: the root on the piece, 2 beside the trunk and 2.2 under its seen foot
    pts = _occluded(np.random.default_rng(1))
    pts[:100, 0] += 2.0
    assert abs(prepared_root(pts)[2] - 2.7) < 0.05


def _leaning(seed: int, lean: float, gap: tuple[float, float] | None, n: int = 20000,
             half: bool = False) -> np.ndarray:
    """helper-156's tree, 20 tall: a trunk (a quarter of ``n``, radius 0.2) up to 12 leaning ``lean``
    degrees, unseen from ``gap`` [0] to [1] of the height, and a crown from 8 to 20 over its top."""
    rng = np.random.default_rng(seed)
    trunk = _cylinder(rng, 0.0, 12.0, 0.2, n // 4, lean, half)
    if gap:
        trunk = trunk[(trunk[:, 2] < 20 * gap[0]) | (trunk[:, 2] > 20 * gap[1])]
    zc = rng.uniform(8, 20, 3 * n // 4)
    rr, b = 5 * np.sin(np.pi * (zc - 8) / 12) * np.sqrt(rng.uniform(0, 1, len(zc))), rng.uniform(0, 2 * np.pi, len(zc))
    return np.r_[trunk, np.c_[np.tan(np.radians(lean)) * 14 + rr * np.cos(b), rr * np.sin(b), zc]]


@pytest.mark.parametrize("seed, lean, gap, n, half", [(0, 10, (0.02, 0.1), 20000, False),
                                                      (1, 30, (0.05, 0.15), 20000, True),
                                                      (9, 30, None, 600, False)])
def test_a_leaning_trunk_s_foot_seen_apart_keeps_the_root(seed, lean, gap, n, half):
    # guard (passed before too): measured at the root found above the gap, not on the axis carried
    # down, helper-155's rule left these feet out and rooted the trees 1.2-3.8 up their trunks
    pts = _leaning(seed, lean, gap, n, half)
    assert np.linalg.norm(prepared_root(pts)) < 0.5


def test_the_axis_is_carried_down_to_the_piece():
    # a trunk leaning 30 degrees seen from 2 up: at height 0 its axis stands 1.15 back, not at the root
    pts = _cylinder(np.random.default_rng(0), 2.0, 12.0, 0.2, 4000, 30)
    root = np.array([2.0 * np.tan(np.radians(30)), 0.0, 2.0])
    assert np.allclose(_axis_at(pts, root, 20.0, 0.0), [0.0, 0.0], atol=0.05)
    foot = _cylinder(np.random.default_rng(1), 0.0, 0.4, 0.2, 200, 30)
    assert under(foot, pts, root, 20.0)
    assert not under(foot + [1.5, 0.0, 0.0], pts, root, 20.0)  # the same piece 1.5 beside it: no foot


def test_too_few_points_above_keep_the_root_as_the_axis():
    pts = _cylinder(np.random.default_rng(0), 2.0, 2.1, 0.2, 50)  # 0.1 of 20 high: under LINK
    assert np.array_equal(_axis_at(pts, np.array([0.3, 0.1, 2.0]), 20.0, 0.0), [0.3, 0.1])


def test_a_sparse_trunk_under_branch_layers_keeps_its_foot():
    # guard (passed before too): 300 trunk points through five 3,000-point layers, a piece of the trunk
    # apart at 0.8-2.1: the axis fitted through the lowest layer lies 1.1 off the trunk, so with the axis
    # alone the piece was left out and the root went 2.5 up (the root's own position keeps it)
    assert prepared_root(layered_tree(1, 300, 0.2))[2] < 1.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_stump_beside_a_groundless_tree_is_no_root(seed):
    # before: the root on the stump (600 points, 0.8 tall, 1.5 from the trunk), 1.5 off
    rng = np.random.default_rng(100 + seed)
    pts = np.r_[_leaning(seed, 0, None), _cylinder(rng, 0.0, 0.8, 0.3, 600) + [1.5, 0.0, 0.0]]
    assert np.linalg.norm(prepared_root(pts)[:2]) < 0.1


@pytest.mark.parametrize("lean", [0, 20])
def test_a_clump_s_lone_points_go_with_it(lean):
    # a clump of 2 % 5 % of the height under a tree whose foot is seen apart (trunk unseen from 2 to 6 %
    # of the height): a lone point of the clump, beyond the 2 % links, was left behind and the root
    # found again took its height, 1.55 under the foot (7.8 % of the height); now it goes with the clump
    pts = _leaning(0, lean, (0.02, 0.06))
    root = prepared_root(np.r_[pts, _clump(pts, 0.02, 0.05, 0.15)])
    assert abs(root[2]) < 0.05 and np.linalg.norm(root[:2]) < 0.2


def test_the_piece_left_out_gets_its_own_note():
    from arboretum_server.decompose.notes import scan_notes

    notes = scan_notes({"apart": 140, "strays": 0})
    assert len(notes) == 1 and notes[0].startswith("140 points under the tree left out: a small piece apart")
    assert scan_notes({"apart": 0}) == []


def _sparse_root_error(model: str, species: str, seed: int, scan: str, n: int, draw: int) -> tuple[float, int]:
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.preprocess import prepare
    from arboretum_server.decompose.report import grow_truth, virtual_scan
    from arboretum_server.decompose.toytree import toy_scan

    tr = grow_truth(model, species, seed)
    h = float(np.ptp(tr.positions[:, 2]))
    foot = tr.positions[np.argmin(tr.positions[:, 2])]
    if scan == "virtual":
        cloud = virtual_scan(tr, "leaf-on", seed)[0]
    else:
        cloud = toy_scan(tr, n=40000, noise=0.002 * h, seed=seed)[0]
    q = cloud[np.random.default_rng(draw).choice(len(cloud), n, replace=False)]
    o = DecomposeOptions()
    p = prepare(q, o, np.random.default_rng(o.seed))
    return float(np.linalg.norm(p.root_scan - foot)) / h, p.apart


@pytest.mark.parametrize("args", [("guiding", "default", 1, "virtual", 2500, 250000),
                                  ("guiding", "default", 2, "toy", 1000, 100001)])
def test_a_sparse_trunks_own_foot_is_not_a_piece_apart(args):
    # helper-161's review of the first version: the foot of a 1,000-2,500-point tree, its points just
    # over LINK apart, came out as a piece; the root went 7-11 % of the height up the trunk
    err, apart = _sparse_root_error(*args)
    assert apart == 0 and err < 0.02
