"""A synthetic HBL with ellipsoidal lobes (icosphere hulls), for demos, tests and benchmarks."""

from __future__ import annotations

import numpy as np

from arboretum_library.model import HBL, Branch, Level, Lobe


def icosphere(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: vertices (V, 3) and outward faces (F, 3) int32 (20 × 4^subdivisions faces)."""
    g = (1 + 5**0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g], [0, -1, -g],
                  [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], np.int64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq].mean(1)
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = len(v) + inv.ravel().reshape(3, -1).T  # midpoints of edges (01, 12, 20) per face
        v = np.concatenate([v, mid])
        a, b, c = f.T
        f = np.concatenate([np.c_[a, m[:, 0], m[:, 2]], np.c_[b, m[:, 1], m[:, 0]],
                            np.c_[c, m[:, 2], m[:, 1]], m])
    return v, f.astype(np.int32)


def ellipsoid_lobe(rng: np.random.Generator, centre: np.ndarray, radii: np.ndarray, branch: int,
                   subdivisions: int = 2, n_points: int = 50) -> Lobe:
    """A lobe whose hull is an ellipsoid with semi-axes ``radii`` (3,) around ``centre`` (3,)."""
    v, f = icosphere(subdivisions)
    members = centre + rng.normal(size=(n_points, 3)) * radii * 0.3
    return Lobe(members, centre + v * radii, f, centre, branch)


def demo_hbl(rng: np.random.Generator, n_lobes: int = 50, height: float = 6.0, n_main: int = 4) -> HBL:
    """A trunk with ``n_main - 1`` scaffold branches and ``n_lobes`` secondary branches, each ending
    a little inside its own ellipsoidal lobe (semi-axes about 0.35-0.6 m)."""
    n = 16
    trunk = np.c_[rng.normal(0, 0.02, n).cumsum() * 0.2, rng.normal(0, 0.02, n).cumsum() * 0.2,
                  np.linspace(0, height, n)]
    branches = [Branch(trunk, np.linspace(0.18, 0.05, n))]
    for k in range(1, n_main):
        vertex = 5 + (k * 3) % (n - 7)
        ang = 2 * np.pi * k / (n_main - 1) + rng.uniform(-0.3, 0.3)
        d = np.array([np.cos(ang), np.sin(ang), 1.1])
        pts = trunk[vertex] + np.linspace(0, 2.2, 8)[:, None] * d / np.linalg.norm(d)
        branches.append(Branch(pts, np.linspace(0.08, 0.03, 8), 0, vertex, Level.MAIN))
    lobes = []
    for j in range(n_lobes):
        parent = j % len(branches)
        ppts = branches[parent].points
        vertex = int(rng.integers(len(ppts) // 3, len(ppts)))
        ang = rng.uniform(0, 2 * np.pi)
        d = np.array([np.cos(ang), np.sin(ang), rng.uniform(0.2, 0.9)])
        d /= np.linalg.norm(d)
        reach = rng.uniform(0.6, 1.3)
        tip = ppts[vertex] + reach * d
        pts = ppts[vertex] + np.linspace(0, 1, 5)[:, None] * (tip - ppts[vertex])
        branches.append(Branch(pts, np.linspace(0.03, 0.012, 5), parent, vertex, Level.SECONDARY))
        radii = rng.uniform(0.35, 0.6, 3) * np.array([1, 1, 0.8])
        lobes.append(ellipsoid_lobe(rng, tip + d * radii.min() * 0.6, radii, len(branches) - 1))
    return HBL(trunk[0], tuple(branches), tuple(lobes))
