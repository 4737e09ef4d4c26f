"""Ground (session 23, helper-161): a tree mirrored under its ground (multipath off wet ground or a
puddle: a share of ALL its points, crown and trunk, at z -> 2 z_ground - z) had no ground found: scan 10
(its 16 columns too few to fit a plane) and a eucalyptus (its mirror held 2 % of its points under the
ground), 12 of 110 clouds. And scan 10 thinned to 4,000 points with 10-20 % uniform outliers held too
few columns to fit its ground to (no ground in 30 of 30 draws, the root 2.8-4.9 % of the height low)."""

import numpy as np
import pytest

from arboretum_server.decompose.ground import find_ground
from factories import prepared_root, real_scan, strewn, trunk_on_disc


def mirrored(pts: np.ndarray, share: float, seed: int, ground: float = 0.0) -> np.ndarray:
    """``share`` of the points of ``pts`` (N, 3), drawn with ``seed``, mirrored in the plane z = ``ground``."""
    rng = np.random.default_rng(seed)
    m = pts[rng.choice(len(pts), int(share * len(pts)), replace=False)]
    return m * [1, 1, -1] + [0, 0, 2 * ground]


@pytest.mark.parametrize("share", [0.002, 0.03])
def test_scan_10_mirrored_under_its_ground_keeps_its_ground(share):
    # before: no ground (its 2.4 m wide cloud stretched to 34 m tall held 16 columns)
    pts, _ = real_scan("10")
    clean, surface = find_ground(pts, 0.015)
    xy = np.median(pts[clean, :2], axis=0, keepdims=True)
    z0 = float(surface.height(xy)[0])
    mirror = mirrored(pts, share, 0, z0)
    ground, found = find_ground(np.r_[pts, mirror], 0.015)
    assert found is not None and abs(float(found.height(xy)[0]) - z0) < 0.01 * np.ptp(pts[:, 2])
    assert ground[len(pts):].all()  # the mirror cut with the ground


def dense_trunk_on_disc(seed: int, n_trunk: int) -> np.ndarray:
    """``trunk_on_disc`` with ``n_trunk`` trunk points: a densely seen trunk, whose mirror holds itself."""
    rng = np.random.default_rng(seed)
    a, z = rng.uniform(0, 2 * np.pi, n_trunk), rng.uniform(0, 10, n_trunk)
    return np.r_[trunk_on_disc(rng)[:8000], np.c_[0.1 * np.cos(a), 0.1 * np.sin(a), z],
                 np.c_[rng.normal(0, 1, (6000, 2)), rng.uniform(4, 10, 6000)]]


@pytest.mark.parametrize("n_trunk, share", [(12000, 0.03), (20000, 0.02), (20000, 0.05)])
def test_a_mirror_of_a_dense_trunk_is_cut_with_the_ground(n_trunk, share):
    # before: no ground: the mirror held over GROUND_BELOW of the points under it, and its trunk held
    # itself GROUND_HELD deep, so the held pass did not look past it either
    pts = dense_trunk_on_disc(0, n_trunk)
    mirror = mirrored(pts[8000:], share, 1)  # trunk and crown, not the disc
    ground, found = find_ground(np.r_[pts, mirror], 0.015)
    assert found is not None and abs(float(found.height(np.zeros((1, 2)))[0])) < 0.05
    assert ground[len(pts):].all() and ground[:8000].mean() > 0.95


def test_a_trunk_mirrored_alone_under_a_layer_is_no_mirror():
    # a guard: a crown's underside with the trunk under it mirrors onto the trunk above, but spreads
    # like a trunk, not like the tree: no ground
    rng = np.random.default_rng(2)
    a, z = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(-4, 10, 3000)
    trunk = np.c_[0.1 * np.cos(a), 0.1 * np.sin(a), z]
    layer = np.c_[rng.uniform(-3, 3, (9000, 2)), rng.normal(0, 0.02, 9000)]
    crown = np.c_[rng.normal(0, 1, (6000, 2)), rng.uniform(4, 10, 6000)]
    ground, found = find_ground(np.r_[layer, trunk, crown], 0.015)
    assert found is None and ground.sum() == 0


@pytest.mark.parametrize("share, seed", [(0.1, 0), (0.15, 3), (0.2, 4)])
def test_scan_10_thinned_with_outliers_keeps_its_root(share, seed):
    # before: no ground and the root 2.8-3.9 % of the height low (0 of 30 draws right, now 25)
    pts, root = real_scan("10")
    thin = pts[np.sort(np.random.default_rng(seed).choice(len(pts), 4000, replace=False))]
    cloud = np.r_[thin, strewn(thin, share, seed)]
    assert np.linalg.norm(prepared_root(cloud) - root) < 0.01 * np.ptp(pts[:, 2])


def test_the_foot_of_a_leafy_tree_with_no_ground_is_no_mirror():
    # a guard: the harmonic pine 3's toy scan (leaf-on, no ground) landed 75 % of its lowest metre on its
    # foliage above a surface 1 m up, mirrored: it was cut as a mirrored ground until the mirror had to
    # reach half as deep as the tree stands tall
    from arboretum_server.decompose.report import CASES, grow_truth
    from arboretum_server.decompose.toytree import toy_scan

    truth = grow_truth("harmonic", "pine", 3)
    noise = 0.002 * float(np.ptp(truth.positions[:, 2]))
    pts, _ = toy_scan(truth, n=40000, noise=noise, seed=3, **CASES["leaf-on"])
    ground, found = find_ground(pts, 0.015)
    assert found is None and ground.sum() == 0


def test_equal_flat_whorls_over_a_bare_trunk_are_no_mirror():
    # helper-163's review: a groundless pole with 8 equal whorls 1 m apart mirrors whorl onto whorl in the
    # plane of the 5.2 m whorl; everything under it (4,839 points, trunk and lowest whorl) was cut
    rng = np.random.default_rng(0)

    def cyl(n, z0, z1):
        a, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(z0, z1, n)
        return np.c_[0.1 * np.cos(a), 0.1 * np.sin(a), z]

    def whorl(z):
        r, b = np.sqrt(rng.uniform(0, 1, 4000)), rng.uniform(0, 2 * np.pi, 4000)
        return np.c_[r * np.cos(b), r * np.sin(b), z + rng.normal(0, 0.003, 4000)]

    pts = np.r_[cyl(1200, 0, 12), cyl(300, 0, 0.5), *[whorl(z) for z in np.arange(4.2, 12, 1.0)]]
    ground, surface = find_ground(pts, 0.015)
    assert surface is None and ground.sum() == 0
