"""The virtual scanner: labels, occlusion, noise, missing sector, budget, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from arboretum_library.geometry import quat_to_matrix
from arboretum_library.truth import LEAF_WIDTH_RATIO, TreeTruth
from arboretum_server.synth.guiding import grow_guiding
from arboretum_server.synth.presets import preset
from arboretum_server.synth.scanner import ScanOptions, scan


@pytest.fixture(scope="module")
def tree() -> TreeTruth:
    return grow_guiding(preset("default", nodes=12000), 4, "default")


def _cone_distance(q, a, b, ra, rb):
    ab = b - a
    t = np.clip(((q - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    axis_d = np.linalg.norm(q - (a + t[..., None] * ab), axis=-1)
    return np.abs(axis_d - (ra + t * (rb - ra)))


def _leaf_distance(q, centre, R, size):
    local = np.einsum("...ji,...j->...i", R, q - centre)
    ax, by = 0.5 * size, 0.5 * LEAF_WIDTH_RATIO * size
    s = np.sqrt((local[..., 0] / ax) ** 2 + (local[..., 1] / by) ** 2)
    scale = np.where(s > 1, 1 / np.maximum(s, 1e-12), 1.0)
    off = local[..., :2] * (1 - scale[..., None])
    return np.sqrt(local[..., 2] ** 2 + (off**2).sum(-1))


def _nearest_elements(tr: TreeTruth, q: np.ndarray, k: int = 16):
    """(label, branch id) of the nearest cone or leaf to each point (checked among the k nearest)."""
    ch = np.arange(1, tr.node_count)
    a, b = tr.positions[tr.parent[ch]], tr.positions[ch]
    _, ci = cKDTree((a + b) / 2).query(q, k)
    dw = _cone_distance(q[:, None], a[ci], b[ci], tr.radii[tr.parent[ch]][ci], tr.radii[ch][ci])
    R = np.stack([quat_to_matrix(w) for w in tr.leaf_wxyz])
    _, li = cKDTree(tr.leaf_positions).query(q, k)
    dl = _leaf_distance(q[:, None], tr.leaf_positions[li], R[li], tr.leaf_sizes[li])
    wood_best, leaf_best = dw.min(1), dl.min(1)
    wood_bid = tr.branch_id[ch[ci[np.arange(len(q)), dw.argmin(1)]]]
    leaf_bid = tr.branch_id[tr.leaf_node[li[np.arange(len(q)), dl.argmin(1)]]]
    is_leaf = leaf_best < wood_best
    return is_leaf.astype(np.uint8), np.where(is_leaf, leaf_bid, wood_bid)


def test_labels_agree_with_nearest_truth_element(tree):
    s = scan(tree, ScanOptions(points=6000, noise=0.001), np.random.default_rng(1))
    label, bid = _nearest_elements(tree, s.points)
    wood, leaf = s.labels == 0, s.labels == 1
    assert wood.sum() > 1000 and leaf.sum() > 1000
    assert (label[wood] == 0).mean() >= 0.98
    assert ((label == 0) & (bid == s.branch_ids))[wood].mean() >= 0.98
    assert (label[leaf] == 1).mean() >= 0.98


def test_exact_budget_and_fewer_when_occluded(tree):
    s = scan(tree, ScanOptions(points=5000), np.random.default_rng(2))
    assert (
        s.points.shape == (5000, 3)
        and s.labels.dtype == np.uint8
        and s.branch_ids.dtype == np.int32
    )
    few = scan(
        tree, ScanOptions(points=20000, oversample=1.0, scanners=1), np.random.default_rng(2)
    )
    assert 1000 < len(few.points) < 20000


def test_occlusion_hides_the_far_side():
    """A single trunk seen from one station: only its near half returns; a leaf in front hides it."""
    tr = TreeTruth(positions=[[0, 0, 0], [0, 0, 1.0], [0, 0, 2.0]], radii=[0.1, 0.1, 0.1], parent=[-1, 0, 1],
                   branch_id=[0, 0, 0], branch_order=[0, 0, 0])  # fmt: skip
    opts = ScanOptions(points=3000, scanners=1, distance=5.0, scanner_height=1.0, noise=0.0)
    s = scan(tr, opts, np.random.default_rng(3))
    to_station = s.stations[0, :2] - s.points[:, :2]
    assert ((s.points[:, :2] * to_station).sum(1) > -1e-9).all()  # every point faces the station
    card = np.array([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0])  # card normal along +X
    d = np.append(s.stations[0, :2], 0.0) / np.linalg.norm(s.stations[0, :2])
    yaw = np.arctan2(d[1], d[0])
    qz = np.array([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])
    wxyz = _qmul(qz, card)
    leafy = TreeTruth(positions=tr.positions, radii=tr.radii, parent=tr.parent, branch_id=tr.branch_id,
                      branch_order=tr.branch_order, leaf_positions=[d * 1.0 + [0, 0, 1.0]],
                      leaf_wxyz=[wxyz], leaf_sizes=[0.8], leaf_node=[1])  # fmt: skip
    s2 = scan(leafy, opts, np.random.default_rng(3))
    wood = s2.points[s2.labels == 0]
    behind = np.abs(wood[:, 2] - 1.0) < 0.05
    assert (s2.labels == 1).sum() > 100
    assert behind.sum() < 0.2 * (np.abs(s.points[:, 2] - 1.0) < 0.05).sum()


def _qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])  # fmt: skip


def test_range_noise_has_the_asked_sigma():
    tr = TreeTruth(positions=[[0, 0, 0], [0, 0, 3.0]], radii=[0.3, 0.3], parent=[-1, 0], branch_id=[0, 0],
                   branch_order=[0, 0])  # fmt: skip
    s = scan(tr, ScanOptions(points=4000, noise=0.01, distance=6.0), np.random.default_rng(4))
    radial = np.hypot(s.points[:, 0], s.points[:, 1]) - 0.3
    inner = (s.points[:, 2] > 0.2) & (s.points[:, 2] < 2.8)
    assert 0.007 < radial[inner].std() < 0.012  # noise along the ray, mostly radial here


def test_leaf_off_and_missing_sector(tree):
    off = scan(tree, ScanOptions(points=4000, leaf_off=True), np.random.default_rng(5))
    assert (off.labels == 0).all() and len(off.points) == 4000
    full = scan(tree, ScanOptions(points=4000), np.random.default_rng(5))
    cut = scan(
        tree,
        ScanOptions(points=4000, missing_sector=90, missing_azimuth=30),
        np.random.default_rng(5),
    )
    root = tree.positions[0]

    def inside(p):
        az = np.degrees(np.arctan2(p[:, 1] - root[1], p[:, 0] - root[0]))
        return np.mod(az - 30, 360) < 90

    assert inside(full.points).sum() > 400
    assert (
        inside(cut.points).sum() < 0.02 * inside(full.points).sum()
    )  # only range noise crosses back
    assert len(cut.points) == 4000


def test_scan_is_deterministic(tree):
    a = scan(tree, ScanOptions(points=3000), np.random.default_rng(9))
    b = scan(tree, ScanOptions(points=3000), np.random.default_rng(9))
    c = scan(tree, ScanOptions(points=3000), np.random.default_rng(10))
    assert np.array_equal(a.points, b.points) and np.array_equal(a.branch_ids, b.branch_ids)
    assert not np.array_equal(a.points, c.points)


def test_labels_on_a_harmonic_tree():
    harmonic = pytest.importorskip("arboretum_server.synth.harmonic")
    if not hasattr(harmonic, "grow_species"):
        pytest.skip("the harmonic model is not built yet")
    tr = harmonic.grow_species("pine", 3)
    s = scan(tr, ScanOptions(points=4000, noise=0.001), np.random.default_rng(1))
    label, bid = _nearest_elements(tr, s.points)
    wood = s.labels == 0
    assert wood.sum() > 500 and (s.labels == 1).sum() > 500
    assert ((label == 0) & (bid == s.branch_ids))[wood].mean() >= 0.95
    assert (label[~wood] == 1).mean() >= 0.95
