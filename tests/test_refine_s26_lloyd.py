"""``refine.stroke_parts``' k-means stops once a round assigns every point as the round before (session 26,
helper-186): from then on every round repeats it, so the split is the one all ``LLOYD_ROUNDS`` rounds give
(the bench's splits settle after 3 to 8 of the 10). Checked against the loop it replaces."""

from __future__ import annotations

import numpy as np


def _reference_lloyd(pts, centres, rounds):
    """``stroke_parts``' k-means before session 26: every round, then the final assignment."""
    from scipy.spatial import cKDTree

    for _ in range(rounds):
        nearest = cKDTree(centres).query(pts)[1]
        count = np.bincount(nearest, minlength=len(centres))
        sums = np.stack([np.bincount(nearest, pts[:, a], minlength=len(centres)) for a in range(3)], axis=1)
        centres = np.where(count[:, None] > 0, sums / np.maximum(count, 1)[:, None], centres)
    return cKDTree(centres).query(pts)[1]


def test_lloyd_stopping_early_gives_the_assignment_of_every_round(rng):
    from arboretum_server.decompose.refine import LLOYD_ROUNDS, _lloyd

    differ_from_first = 0
    for trial in range(60):
        pts = rng.normal(0, 1, (int(rng.integers(20, 300)), 3)) * rng.uniform(0.2, 2, 3)
        centres = rng.normal(0, 1.5, (int(rng.integers(2, 40)), 3))  # far ones stay empty
        if trial % 3 == 0:
            centres[: len(centres) // 2] = pts[rng.choice(len(pts), len(centres) // 2, replace=False)]
        want = _reference_lloyd(pts, centres, LLOYD_ROUNDS)
        assert np.array_equal(_lloyd(pts, centres), want)
        differ_from_first += not np.array_equal(want, _reference_lloyd(pts, centres, 1))
    assert differ_from_first > 30  # the cases need more than one round

