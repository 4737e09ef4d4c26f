"""A clump centred under a groundless tree's trunk (session 24, helper-170).

Session 23's ``under`` keeps a piece apart under the tree when it stands under the trunk: a real foot seen
behind a scan gap does. A clump centred there stood under it too and stayed the root (27 of 90 clumps
under scans 01, 06, 07). A foot is bark round the trunk's axis, a ring in plan; a clump fills a disc
(``_filled``: the share of its points within ``HOLLOW_CORE`` of their median distance from the circle
fitted to them). A filled piece is no foot, and is a piece apart when a link's length (not 1.5) parts it
from the tree: a clump 5 % of the height under the foot touches the 3 % floor.
"""

import numpy as np
import pytest

import arboretum_server.decompose.trunkbase_piece as piece
from arboretum_server.decompose.trunkbase import detached, find_root, under
from factories import prepared_root, real_scan
from test_trunks_s23_clumps import _clump, _cylinder, _leaning


def _core_share(xy: np.ndarray, core: float = 0.4) -> float:
    """The share of ``xy`` (M, 2) within ``core`` of their median distance from their fitted circle's centre
    (``HOLLOW_CORE``: 0.4)."""
    a = np.c_[2.0 * xy, np.ones(len(xy))]
    centre = np.linalg.lstsq(a, (xy ** 2).sum(axis=1), rcond=None)[0][:2]
    d = np.linalg.norm(xy - centre, axis=1)
    return float((d < core * np.median(d)).mean())


@pytest.mark.parametrize("key, share, below", [("01", 0.01, 0.1), ("06", 0.03, 0.2), ("07", 0.02, 0.1),
                                               ("01", 0.02, 0.05), ("06", 0.03, 0.05), ("07", 0.01, 0.05)])
def test_a_clump_centred_under_a_groundless_scan_is_left_out(key, share, below):
    # before: the root on the clump, 7.5-23 % of the height under the scan's own (at 5 % under, the clump
    # lay 1.3-1.5 links under the foot: no piece apart; deeper, it stood under the trunk and stayed)
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.preprocess import prepare

    pts, clean = real_scan(key)
    blob = _clump(pts, share, below, 0.0)
    o = DecomposeOptions()
    p = prepare(np.r_[pts, blob], o, np.random.default_rng(o.seed))
    assert np.linalg.norm(p.root_scan - clean) < 0.01 * np.ptp(pts[:, 2])
    assert not np.isin(p.source_index, np.arange(len(pts), len(pts) + len(blob))).any()


@pytest.mark.parametrize("lean, gap", [(0, None), (20, (0.02, 0.06)), (30, None)])
def test_a_clump_under_a_leaning_trunk_is_left_out(lean, gap):
    # before: the root on the clump (2 % of the points, 10 % of the height under the foot, centred), 2 low
    pts = _leaning(0, lean, gap)
    root = prepared_root(np.r_[pts, _clump(pts, 0.02, 0.1, 0.0)])
    assert abs(root[2]) < 0.05 and np.linalg.norm(root[:2]) < 0.2


def test_a_blob_fills_and_a_ring_does_not():
    rng = np.random.default_rng(0)
    blob = rng.normal(0, 1, (2000, 2))  # a Gaussian blob: 1 - exp(-(0.4 * 1.1774) ** 2 / 2) = 10.5 %
    a = rng.uniform(0, 2 * np.pi, 200)
    ring = np.c_[np.cos(a), np.sin(a)] * (1 + rng.normal(0, 0.03, 200))[:, None]
    half = ring[ring[:, 0] < 0] + [5.0, 3.0]  # a foot seen from one side: its arc finds the centre
    assert (piece.HOLLOW_CORE, piece.FILLED_SHARE) == (0.4, 0.04)
    assert abs(_core_share(blob) - 0.105) < 0.01 and piece._filled(blob)
    assert _core_share(ring) == 0.0 and not piece._filled(ring)
    assert _core_share(half) == 0.0 and not piece._filled(half)


def test_a_leaning_foot_is_measured_along_the_axis():
    # a foot 1 tall under a trunk leaning 30 degrees, unseen from 1 to 3: its plan smears into a disc,
    # seen across the axis's slope it is a ring and stays the root
    rng = np.random.default_rng(3)
    foot, trunk = _cylinder(rng, 0.0, 1.0, 0.2, 300, 30), _cylinder(rng, 3.0, 12.0, 0.2, 3000, 30)
    assert piece._filled(foot[:, :2])
    assert under(foot, trunk, find_root(trunk), 20.0)


@pytest.mark.parametrize("key, lo, length", [("01", 0.02, 0.06), ("06", 0.01, 0.1), ("07", 0.02, 0.1),
                                             ("07", 0.03, 0.15)])
def test_a_scan_s_foot_behind_a_gap_keeps_the_root(key, lo, length):
    # guard (passed before too): the scan's trunk cut from lo to lo + length of the height above its
    # lowest point; its foot comes out as a piece apart under the trunk and stays the root. The
    # buttressed scan 07's foot is the least hollow seen: 0-1.4 % of its points in the core
    pts, clean = real_scan(key)
    h = float(np.ptp(pts[:, 2]))
    z = pts[:, 2] - pts[:, 2].min()
    cut = pts[(z < lo * h) | (z > (lo + length) * h)]
    assert np.linalg.norm(prepared_root(cut) - clean) < 0.01 * h
    piece = detached(cut, cut[:, 2], find_root(cut))
    assert piece.sum() >= 10 and _core_share(cut[piece, :2]) < 0.02  # FILLED_SHARE: 0.04
