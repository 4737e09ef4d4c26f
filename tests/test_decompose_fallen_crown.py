"""A weeping crown bent down to the ground: its leaves fill the lowest 3 % of the cloud beside the trunk.

The guiding-vector elm's crown, bent down 90 % at its rim, put the root on a mat of its leaves 0.49
of the height from the trunk, without a word; bent 95 % it was refused as "flat patches". Its
leaves lie in mats wider than a trunk with the crown above them, and the trunk is the one full,
narrow column among the clusters of the band (``trunkbase._trunks_under_fallen_crown``).
"""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from arboretum_server.decompose.toytree import toy_scan

OPTS = DecomposeOptions(n_main=6, n_lobes=20)


@pytest.fixture(scope="module")
def elm():
    """(points, true trunk base (3,), height) of the guiding elm's toy scan, leaf-on, 40,000 points."""
    from arboretum_server.synth.guiding import grow_guiding
    from arboretum_server.synth.presets import preset

    truth = grow_guiding(preset("elm"), 1, "elm")
    pts, _ = toy_scan(truth, n=40000, noise=0.002 * float(np.ptp(truth.positions[:, 2])), seed=1)
    base = truth.positions[0].copy()
    base[2] = pts[:, 2].min()
    return pts, base, float(pts[:, 2].max() - base[2])


def bend(pts: np.ndarray, base: np.ndarray, h: float, amount: float) -> np.ndarray:
    """The crown bent down: a point's height above the base shrinks by ``amount`` at the crown's rim,
    smoothly less inwards, not at all within 6 % of the height of the trunk axis."""
    r = np.linalg.norm(pts[:, :2] - base[:2], axis=1)
    u = np.clip((r - 0.06 * h) / (np.percentile(r, 99) - 0.06 * h), 0, 1)
    out = pts.copy()
    out[:, 2] = base[2] + (pts[:, 2] - base[2]) * (1 - amount * u * u * (3 - 2 * u))
    return out


@pytest.mark.parametrize("amount", [0.9, 0.95])
def test_the_root_stays_on_the_trunk_of_a_crown_bent_to_the_ground(elm, amount):
    pts, base, h = elm
    bent = bend(pts, base, h, amount)
    z = bent[:, 2]
    rim = np.linalg.norm(bent[:, :2] - base[:2], axis=1) > 0.2 * h
    assert (rim & (z < z.min() + 0.03 * h)).sum() > 500  # the leaves do reach the base band
    d = decompose(bent, OPTS)
    assert np.linalg.norm(d.root_scan - base) < 0.01 * h
    assert len(d.hbl.lobes) == 20


@pytest.mark.parametrize("seed", range(1, 7))
def test_the_root_stays_on_the_trunk_whatever_points_the_downsampling_keeps(elm, seed):
    # the first rule asked the largest cluster to be wider than a trunk: right for 4 of 12 seeds only,
    # since the mats often break into narrower pieces (a reviewer's case; 5 put the root on a mat
    # 0.5 of the height away, 3 refused the tree)
    from arboretum_server.decompose.preprocess import prepare

    pts, base, h = elm
    opts = DecomposeOptions(n_main=6, n_lobes=20, seed=seed)
    prep = prepare(bend(pts, base, h, 0.9), opts, np.random.default_rng(seed))
    assert np.linalg.norm(prep.root_scan - base) < 0.01 * h


def test_two_bent_crowns_are_still_two_trees(elm):
    # their 12,000 points leave no big cluster in the band (each trunk holds 10 points there, the leaves
    # 27 at most), so the largest cluster was all of it: "no trunk base found (spreads 7.31 wide)"
    pts, base, h = elm
    bent = bend(pts, base, h, 0.9)
    with pytest.raises(InputError, match="2 separate trunks"):
        decompose(np.vstack([bent, bent + [0.6 * h, 0.0, 0.0]]), OPTS)



def test_a_band_of_scattered_points_is_still_no_trunk_base():
    # a Gaussian blob's lowest 3 % holds scattered points and no cluster of 10: the search for trunks
    # among the clusters found none to measure (a ValueError before the probe caught it)
    blob = np.random.default_rng(5).normal(0, 1, (20000, 3))
    with pytest.raises(InputError, match="no trunk base found"):
        decompose(blob, OPTS)


def test_a_dense_base_band_is_clustered_on_a_sample_with_the_same_clusters():
    # a million-point cloud with --points 0 filled the band with 30,000 points, whose pairs within 2 %
    # of the height took 9 GB; a band over LINK_MAX points is clustered on a sample of them
    from arboretum_server.decompose import trunkbase_links

    rng = np.random.default_rng(0)
    h = 10.0
    trunks = [np.c_[c + rng.uniform(-0.1, 0.1, (6000, 2)), rng.uniform(0, 0.3, 6000)] for c in ((0, 0), (3, 0))]
    stray = np.array([[1.5, 5.0, 0.1]])  # far from every point
    band = np.vstack([*trunks, stray])
    assert len(band) > trunkbase_links.LINK_MAX
    lab = trunkbase_links._link(band, trunkbase_links.LINK * h)
    assert len(set(lab[:6000])) == 1 and len(set(lab[6000:12000])) == 1
    assert len({lab[0], lab[6000], lab[-1]}) == 3
    assert np.bincount(lab).max() == 6000
