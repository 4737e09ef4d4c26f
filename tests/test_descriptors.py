"""Descriptors and tags: curvature in radians, tags at their documented thresholds."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.descriptors import TagThresholds, describe, polyline_curvature, tags_for
from arboretum_library.model import HBL, Branch, Descriptors, Lobe

TETRA_F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def test_curvature_of_straight_and_quarter_circle():
    z = np.linspace(0, 1, 50)
    assert polyline_curvature(np.c_[0 * z, 0 * z, z]) == pytest.approx(0, abs=1e-9)
    t = np.linspace(0, np.pi / 2, 200)
    arc = np.c_[1 - np.cos(t), 0 * t, np.sin(t)]
    assert polyline_curvature(arc) == pytest.approx(np.pi / 2, rel=0.02)
    noisy = np.c_[np.random.default_rng(0).normal(0, 0.002, 50), 0 * z, z]
    assert polyline_curvature(noisy) < 0.15  # resampling ignores zig-zag of graph paths
    t = np.linspace(0, np.pi, 300)
    assert polyline_curvature(np.c_[1 - np.cos(t), 0 * t, np.sin(t)]) == pytest.approx(np.pi, rel=0.02)


def test_wiggles_left_by_smoothed_graph_paths_do_not_make_a_branch_curved():
    """A straight branch with a 1 %-of-length wiggle of 5 periods: its chords turned by 0.62 rad in all
    (the total turning angle measured before: between 'straight' and 'curved'); it bows by 0.03."""
    z = np.linspace(0, 1, 400)
    wiggly = np.c_[0.01 * np.sin(2 * np.pi * 5 * z), 0 * z, z]
    assert polyline_curvature(wiggly) < 0.35 / 3
    bowed = np.c_[0.1 * np.sin(np.pi * z), 0 * z, z]  # bows 10 % of its chord: an arc of 4 atan(0.2)
    assert polyline_curvature(bowed) == pytest.approx(4 * np.arctan(0.2), rel=0.05)


def test_describe_counts_lobes_and_spread():
    main = Branch(np.c_[np.zeros(5), np.zeros(5), np.linspace(0, 2, 5)], np.full(5, 0.05))
    lobes = [Lobe(np.zeros((0, 3)), np.eye(4)[:, :3] * 0.1 + c, TETRA_F, c) for c in ([0.5, 0, 1], [0, -0.3, 2.2])]
    d = describe(HBL([0, 0, 0], [main], lobes))
    assert d.lobe_count == 2
    assert d.length == pytest.approx(2.0)
    assert d.spread == pytest.approx((0.5 + np.hypot(0.3, 0.2)) / 2)
    assert d.height == pytest.approx(2.3)


@pytest.mark.parametrize(
    "lobes, curv, expected",
    [(8, 0.1, ("dense", "straight")), (2, 1.0, ("sparse", "curved")), (4, 0.5, ())],
)
def test_tags(lobes, curv, expected):
    assert tags_for(Descriptors(curv, lobes, 1.0, 0.1, 1.0), TagThresholds()) == expected
