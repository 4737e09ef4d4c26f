"""median_spacing (session 10): exact, and its sorting and distances involve only points near the sample."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library import pointio_spatial
from arboretum_library.pointio import median_spacing


def _brute_force(points: np.ndarray, seed: int, samples: int) -> float:
    """The documented meaning: the median over the same random sample of the exact nearest-neighbour
    distance (the sample is drawn exactly as ``median_spacing`` draws it)."""
    query = np.random.default_rng(seed).choice(len(points), min(samples, len(points)), replace=False)
    nearest = []
    for q in query:
        d = np.sqrt(((points - points[q]) ** 2).sum(axis=1))
        d[q] = np.inf
        nearest.append(d.min())
    return float(np.median(nearest))


def _clouds(rng):
    return {
        "tree-like": np.c_[rng.normal(0, 0.3, (3000, 2)), rng.uniform(0, 5, 3000)],
        "flat": np.c_[rng.random((2000, 2)), np.zeros(2000)],
        "line": np.c_[np.linspace(0, 10, 1500), np.zeros(1500), np.zeros(1500)],
        "far clusters and strays": np.r_[
            rng.normal(0, 1e-3, (800, 3)), rng.normal(50, 1e-3, (800, 3)), rng.random((15, 3)) * 1e3
        ],
        "duplicates": np.r_[np.zeros((300, 3)), np.ones((300, 3)), rng.random((300, 3))],
        "two points": np.array([[0.0, 0.0, 0.0], [3e5, 4e5, 0.0]]),
        "tiny": rng.random((500, 3)) * 1e-9,
    }


@pytest.mark.parametrize("name", list(_clouds(np.random.default_rng(0))))
def test_median_spacing_is_exact_for_its_sample(name):
    pts = _clouds(np.random.default_rng(3))[name]
    for seed in (0, 1):
        got = median_spacing(pts, np.random.default_rng(seed), samples=400)
        assert got == pytest.approx(_brute_force(pts, seed, 400), rel=1e-12, abs=0.0)


def test_candidate_slices_give_the_same_result(monkeypatch):
    pts = _clouds(np.random.default_rng(4))["tree-like"]
    want = _brute_force(pts, 2, 500)
    monkeypatch.setattr(pointio_spatial, "CANDIDATE_BUDGET", 40)  # a query or a few per slice
    assert median_spacing(pts, np.random.default_rng(2), samples=500) == pytest.approx(want, rel=1e-12)


def test_spacing_sorts_and_measures_only_points_near_the_sample(monkeypatch, rng):
    """The cost of the spacing grows with the sample: no sort of all N points (before: six argsorts
    of all N cell keys for 2,000 sampled points), no distances beyond the sampled points' cells."""
    n = 200_000
    z = rng.uniform(0, 10, n)
    pts = np.c_[rng.normal(0, 1, n) * z / 10, rng.normal(0, 1, n) * z / 10, z]
    sizes: list[int] = []

    def spy(fn):
        def wrapped(a, *args, **kwargs):
            sizes.append(len(a))  # points (rows) sorted or measured
            return fn(a, *args, **kwargs)

        return wrapped

    for name in ("argsort", "sort", "unique", "lexsort"):
        monkeypatch.setattr(np, name, spy(getattr(np, name)))
    monkeypatch.setattr(np.linalg, "norm", spy(np.linalg.norm))
    got = median_spacing(pts, np.random.default_rng(0), samples=200)
    monkeypatch.undo()
    assert sizes and max(sizes) < n // 10, max(sizes)
    assert got == pytest.approx(_brute_force(pts, 0, 200), rel=1e-12)
