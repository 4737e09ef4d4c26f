"""A tree with no ground among outliers (session 22, helper-153).

A pine 20 tall with a narrow crown (1.2 wide) and no ground, among 5-30 % uniform outliers in a box 20 %
wider than it: in a box that narrow some outliers have 4-6 others within 2 % of the height, so
``_dense_start`` took one on the outliers' floor for the trunk's foot, or, with a ground found on that
floor, the band's largest cluster was outliers linked into a web (52 of 240 draws rooted 5-20 % of the
height low, exit 0). A trunk's foot now needs more neighbours than the outliers' own density gives them
(``_lone_most``), and a web of them is no trunk base (``_strewn``).
"""

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_server.decompose.trunkbase_links import _dense_start
from factories import prepared_root, strewn


def _pine(seed: int, radius: float = 1.2) -> np.ndarray:
    """A tree 20 tall at (0, 0) with no ground: a trunk 0.15 wide (5,000 points) from z = 0, a cone of
    crown ``radius`` wide at 4 (15,000)."""
    rng = np.random.default_rng(seed)
    a, z = rng.uniform(0, 2 * np.pi, 5000), rng.uniform(0, 20, 5000)
    zc = rng.uniform(4, 20, 15000)
    r, b = radius * (20 - zc) / 16 * np.sqrt(rng.uniform(0, 1, len(zc))), rng.uniform(0, 2 * np.pi, len(zc))
    return np.r_[np.c_[0.15 * np.cos(a), 0.15 * np.sin(a), z], np.c_[r * np.cos(b), r * np.sin(b), zc]]


@pytest.mark.parametrize("share, seed", [(0.05, 0), (0.05, 1), (0.1, 0), (0.1, 8), (0.15, 0), (0.15, 1),
                                         (0.2, 4), (0.3, 2)])
def test_a_groundless_pine_among_outliers_is_rooted_on_its_trunk(share, seed):
    # before: rooted 2.2-4.0 under the trunk's foot (on the outliers' floor 4 under it), exit 0
    pine = _pine(seed + 1)
    root = prepared_root(np.r_[pine, strewn(pine, share, seed)])
    assert np.linalg.norm(root) < 0.03 * 20  # outliers next to its foot may join its cluster


def test_dense_start_skips_outliers_with_a_few_neighbours():
    # before: -3.50, an outlier with 5 others within 2 % of the height
    pine = _pine(1)
    pts = np.r_[pine, strewn(pine, 0.1, 0)]
    pts = pts[np.random.default_rng(0).choice(len(pts), 12000, replace=False)]
    h = float(np.ptp(pts[:, 2]))
    assert abs(_dense_start(pts, pts[:, 2], h)) < 0.02 * h  # at most an outlier next to the foot



def _pine_on_patch(seed: int, x0: float) -> np.ndarray:
    """``_pine`` at (``x0``, 0) on a ground patch 2.5 wide (3,000 points, z = 0 +- 0.02)."""
    rng = np.random.default_rng(seed)
    a, z = rng.uniform(0, 2 * np.pi, 5000), rng.uniform(0, 20, 5000)
    zc = rng.uniform(4, 20, 15000)
    r, b = 1.2 * (20 - zc) / 16 * np.sqrt(rng.uniform(0, 1, len(zc))), rng.uniform(0, 2 * np.pi, len(zc))
    ground = np.c_[rng.uniform(-1.25, 1.25, (3000, 2)) + [x0, 0.0], rng.normal(0, 0.02, 3000)]
    return np.r_[ground, np.c_[x0 + 0.15 * np.cos(a), 0.15 * np.sin(a), z],
                 np.c_[x0 + r * np.cos(b), r * np.sin(b), zc]]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_two_pines_whose_patches_start_the_band_are_two_trees(seed):
    # 15 % outliers, no ground found: the band now starts on the patches (no outlier has as many
    # neighbours), joined into one flat cluster; before the check above it, rooted between the pines
    two = np.r_[_pine_on_patch(1, 0.0), _pine_on_patch(2, 3.0)]
    with pytest.raises(InputError, match=r"^point cloud: 2 separate trunks found"):
        prepared_root(np.r_[two, strewn(two, 0.15, seed)])
