"""Several trees among outliers (session 22, helper-148). Two pines 20 tall on ground patches, 3 or 6
apart, with 2-15 % uniform outliers, were accepted as one tree in 23 of 40 clouds of helper-146's harness
(16 of 40 with each patch under its own pine, as here): the ground cut keeps only the trunk of its
narrowest slice, so with outliers widening the slices it cut the other tree's foot 0.45-2.4 above the
ground, at or over the top of the 3 % band where separate trunks are refused. The
several-trees check now also looks at the band just above the ground cut (``find_root``'s ``cut``), or
above a flat patch of ground left over it (a ground found on the outliers' floor, under the real one)."""

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.preprocess import _cut_top, prepare
from arboretum_server.decompose.trunkbase import find_root
from factories import prepared_root, real_scan, strewn


def _pine(seed: int, x0: float) -> np.ndarray:
    """A tree 20 tall at (``x0``, 0) (a trunk 0.15 wide, a cone of crown from 4 up) on a ground patch 2.5
    wide under it at z = 0: 3,000 ground points, 20,000 of the tree."""
    rng = np.random.default_rng(seed)
    a, z = rng.uniform(0, 2 * np.pi, 5000), rng.uniform(0, 20, 5000)
    trunk = np.c_[x0 + 0.15 * np.cos(a), 0.15 * np.sin(a), z]
    zc = rng.uniform(4, 20, 15000)
    r, b = 1.2 * (20 - zc) / 16 * np.sqrt(rng.uniform(0, 1, len(zc))), rng.uniform(0, 2 * np.pi, len(zc))
    ground = np.c_[rng.uniform(-1.25, 1.25, (3000, 2)) + [x0, 0.0], rng.normal(0, 0.02, 3000)]
    return np.r_[ground, trunk, np.c_[x0 + r * np.cos(b), r * np.sin(b), zc]]


@pytest.mark.parametrize("gap, share, seed", [(3.0, 0.1, 1), (3.0, 0.1, 2), (3.0, 0.1, 4), (6.0, 0.1, 1),
                                              (6.0, 0.1, 2), (6.0, 0.05, 2)])
def test_two_pines_among_outliers_are_refused_as_two_trees(gap, share, seed):
    # before: accepted, rooted on one trunk (a note naming the other as a column standing 1.0-2.1 higher)
    two = np.r_[_pine(1, 0.0), _pine(2, gap)]
    with pytest.raises(InputError, match=r"^point cloud: 2 separate trunks found [0-9.]+ apart"):
        prepared_root(np.r_[two, strewn(two, share, seed)])


@pytest.mark.parametrize("share, seed", [(0.1, 0), (0.15, 0), (0.15, 3)])
def test_two_pines_over_a_ground_found_under_theirs_are_refused_as_two_trees(share, seed):
    # the ground found on the outliers' floor 3.8-4.0 under the patches, which stay above the cut and
    # join into one flat cluster with both trunks in it: before, accepted with the root on outliers
    # 0.5-2.8 under the ground, 1.2-1.3 from the nearer trunk; now the band above the patch holds them
    two = np.r_[_pine(1, 0.0), _pine(2, 3.0)]
    with pytest.raises(InputError, match=r"^point cloud: 2 separate trunks found (2\.9[0-9]*|3|3\.0[0-9]*) apart"):
        prepared_root(np.r_[two, strewn(two, share, seed)])


@pytest.mark.parametrize("gap, share, seed", [(5.0, 0.05, 1), (5.0, 0.05, 2), (6.5, 0.02, 1), (8.0, 0.02, 0)])
def test_scan_10_twice_among_outliers_is_refused_as_two_trees(gap, share, seed):
    # before: accepted as one tree in 15 of 27 such clouds (5-8 apart, 2-10 % outliers), 0 now
    pts, _ = real_scan("10")
    a = np.radians(90 * seed + 30)
    turned = np.c_[pts[:, 0] * np.cos(a) - pts[:, 1] * np.sin(a), pts[:, 0] * np.sin(a) + pts[:, 1] * np.cos(a),
                   pts[:, 2]]
    two = np.r_[pts, turned + [gap, 0.0, 0.0]]
    with pytest.raises(InputError, match=r"^point cloud: 2 separate trunks found"):
        prepared_root(np.r_[two, strewn(two, share, seed)])


@pytest.mark.parametrize("share, seed", [(0.05, 0), (0.1, 1), (0.15, 2)])
def test_one_pine_among_outliers_keeps_its_root(share, seed):
    # the band above the ground cut holds the one trunk: nothing refused, the root on the trunk's foot
    pine = _pine(1, 0.0)
    root = prepared_root(np.r_[pine, strewn(pine, share, seed)])
    assert np.linalg.norm(root - prepared_root(pine)) < 0.005 * 20


def _columns(feet: list[tuple[float, float]]) -> np.ndarray:
    """Trunks 0.15 wide at x = 0, 3, ... rising from the given (x, lowest z) to 20, 2,000 points each."""
    rng = np.random.default_rng(0)
    parts = []
    for x, low in feet:
        a, z = rng.uniform(0, 2 * np.pi, 2000), rng.uniform(low, 20, 2000)
        parts.append(np.c_[x + 0.15 * np.cos(a), 0.15 * np.sin(a), z])
    return np.concatenate(parts)


def test_find_root_looks_above_the_ground_cut():
    # one trunk from 0.3, another from 1.5 (its foot cut with the ground up to 1.45): the 3 % band
    # (0.3-0.9) holds one trunk; the band from the cut holds both
    pts = _columns([(0.0, 0.3), (3.0, 1.5)])
    up = pts[:, 2]
    assert np.linalg.norm(find_root(pts, up)[:2]) < 0.05
    with pytest.raises(InputError, match=r"^point cloud: 2 separate trunks found (2\.9[0-9]*|3|3\.0[0-9]*) apart"):
        find_root(pts, up, cut=1.45)
    one = _columns([(0.0, 0.3)])
    assert np.array_equal(find_root(one, one[:, 2], cut=1.45), find_root(one, one[:, 2]))
    assert np.array_equal(find_root(pts, up, cut=0.2), find_root(pts, up))  # a cut under the band: as before


def test_a_rock_top_over_the_ground_cut_is_no_second_trunk():
    # a dome 0.5 wide rising 0.25 over the cut, 3 from the trunk, nothing above it: no trunk column rises
    # from it (the top of a boulder by the trunk, tests/test_ground_s19_share.py), so the root stays
    pts = _columns([(0.0, 0.3)])
    rng = np.random.default_rng(1)
    v = rng.normal(size=(400, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    dome = np.c_[3.0 + 0.5 * v[:, 0], 0.5 * v[:, 1], 1.45 + 0.25 * np.abs(v[:, 2])]
    both = np.r_[pts, dome]
    assert np.array_equal(find_root(both, both[:, 2], cut=1.45), find_root(both, both[:, 2]))


def test_cut_top_is_the_highest_cut_point_over_the_ground():
    class Tilted:
        def height(self, xy):
            return 0.1 * xy[:, 0]

    cut = np.array([[0.0, 0.0, 0.2], [2.0, 5.0, 0.5], [4.0, 0.0, 0.1]])
    assert _cut_top(cut, Tilted()) == pytest.approx(0.3)
    assert _cut_top(cut, None) is None and _cut_top(cut[:0], Tilted()) is None


def test_scan_10_alone_keeps_its_ground_and_root():
    pts, clean = real_scan("10")
    o = DecomposeOptions()
    prepared = prepare(pts, o, np.random.default_rng(o.seed))
    assert np.array_equal(prepared.root_scan, clean) and prepared.ground_removed > 2800
