"""Ground (session 22, helper-151's review of helper-149's ``_trunk_below`` and ``_apart_below``): a
groundless tree whose trunk is unseen for 0.8 m under its lowest branch layer had the layer cut as the
ground with the lower trunk; a trunk mirrored in a puddle, a root plate or a post in a hole, a narrow
column 0.5-1 m under a real ground, had the ground refused; a plumb line's repeated xy under the ground
crashed ``find_ground``."""

import numpy as np
import pytest

from arboretum_server.decompose.ground import find_ground
from factories import layered_tree, trunk_on_disc


def tree(*under: np.ndarray) -> np.ndarray:
    """A 10 m trunk (2,000 points, radius 0.1 m) with a crown over a ground disc of 8,000 points 3 m
    across (seed 0, helper-151's ``cases.tree``), and the points ``under`` added."""
    return np.r_[trunk_on_disc(np.random.default_rng(0)), *under]


def column(x: float, radius: float, n: int, bottom: float, top: float) -> np.ndarray:
    """``n`` points on a vertical cylinder of ``radius`` at (``x``, 0) from ``bottom`` to ``top``."""
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 2 * np.pi, n)
    return np.c_[x + radius * np.cos(a), radius * np.sin(a), rng.uniform(bottom, top, n)]


def found_at_zero(pts: np.ndarray) -> bool:
    """Whether ``find_ground`` finds the disc's ground (within 5 cm under the trunk) and cuts the disc."""
    ground, surface = find_ground(pts, 0.015)
    return surface is not None and abs(float(surface.height(np.zeros((1, 2)))[0])) < 0.05 \
        and ground[:8000].mean() > 0.95


@pytest.mark.parametrize("seed, n_trunk, slope", [(0, 1000, 0.0), (1, 2000, 0.2), (2, 2000, 0.0)])
def test_a_trunk_unseen_under_the_lowest_layer_is_no_ground(seed, n_trunk, slope):
    # before: the trunk under the gap set apart, the layer at 4 m found among the rest and cut as the
    # ground with it (the root 4.2-4.4 m up a tree with no ground)
    pts = layered_tree(seed, n_trunk, slope)
    gap = (np.hypot(pts[:, 0], pts[:, 1]) < 0.2) & (pts[:, 2] > 3.0) & (pts[:, 2] < 3.8)
    ground, surface = find_ground(pts[~gap], 0.015)
    assert surface is None and ground.sum() == 0


@pytest.mark.parametrize("case", ["mirrored trunk", "root plate", "post in a hole"])
def test_a_narrow_column_shallow_under_a_ground_leaves_it_found(case):
    # before: no ground (the trunk went on under it); now the disc, as before session 22
    rng = np.random.default_rng(2)
    under = {"mirrored trunk": lambda: column(0, 0.1, 100, -0.5, 0),  # 0.5 m of 2,000 points over 10 m
             "root plate": lambda: column(0, 0.25, 150, -0.5, -0.05),
             "post in a hole": lambda: column(2, 0.05, 300, -0.6, 3.0)}[case]()
    assert found_at_zero(tree(under + [0, 0, 0.001] * rng.normal(size=(len(under), 1))))


@pytest.mark.parametrize("depth, n", [(0.2, 12), (0.5, 20), (1.5, 20)])
def test_a_plumb_line_under_a_ground_is_cut_with_it(depth, n):
    # before: ValueError (max of an empty array) when 10 or more points under the ground share one xy
    line = np.c_[np.full(n, 2.0), np.full(n, 2.0), np.linspace(-depth, -0.05, n) if n > 12 else np.full(n, -depth)]
    pts = tree(line)
    ground, _ = find_ground(pts, 0.015)
    assert found_at_zero(pts) and ground[-n:].all()
