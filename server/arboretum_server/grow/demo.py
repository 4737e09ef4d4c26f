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


def bezier(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) points of the quadratic Bézier curve p0 -> p2 pulled towards p1."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - s) ** 2 * p0 + 2 * s * (1 - s) * p1 + s**2 * p2


def _taper(base: float, tip_fraction: float, n: int) -> np.ndarray:
    """(n,) radii falling linearly from ``base`` to ``base * tip_fraction``."""
    return base * np.linspace(1.0, tip_fraction, n)


def demo_hbl(rng: np.random.Generator, n_lobes: int = 50, height: float = 6.0, n_main: int = 4) -> HBL:
    """A gently swaying trunk with ``n_main - 1`` curved scaffold branches and ``n_lobes`` curved
    secondary branches, each ending a little inside its own ellipsoidal lobe (semi-axes about
    0.35-0.6 m). Polylines are dense (24 / 16 / 8 vertices) so tubes bend smoothly. Radii are
    pipe-like: a branch starts at 0.6 (main) or 0.45 (secondary) of its parent's radius at the joint
    and tapers, so no child is thicker than its parent and the trunk is the thickest (0.18 m)."""
    n = 24
    z = np.linspace(0, height, n)
    sway, phase = rng.uniform(0.05, 0.15, 2), rng.uniform(0, 2 * np.pi, 2)
    trunk = np.c_[sway[0] * np.sin(1.3 * np.pi * z / height + phase[0]) - sway[0] * np.sin(phase[0]),
                  sway[1] * np.sin(1.1 * np.pi * z / height + phase[1]) - sway[1] * np.sin(phase[1]), z]
    branches = [Branch(trunk, _taper(0.18, 0.25, n))]
    for k in range(1, n_main):
        vertex = 8 + (k * 5) % (n - 12)
        ang = 2 * np.pi * k / (n_main - 1) + rng.uniform(-0.3, 0.3)
        out = np.array([np.cos(ang), np.sin(ang), 0.0])
        p0 = trunk[vertex]
        p1 = p0 + 1.1 * (out + np.array([0, 0, 0.8])) / np.hypot(1, 0.8)
        p2 = p1 + 1.1 * (0.35 * out + np.array([0, 0, 1.0])) / np.hypot(0.35, 1.0)
        base = 0.6 * branches[0].radii[vertex]
        branches.append(Branch(bezier(p0, p1, p2, 16), _taper(base, 0.35, 16), 0, vertex, Level.MAIN))
    lobes = []
    for j in range(n_lobes):
        parent = j % n_main  # secondaries hang on the trunk and the scaffolds, as in an HBL
        ppts = branches[parent].points
        vertex = int(rng.integers(len(ppts) // 3, len(ppts)))
        ang = rng.uniform(0, 2 * np.pi)
        d = np.array([np.cos(ang), np.sin(ang), rng.uniform(0.2, 0.9)])
        d /= np.linalg.norm(d)
        reach = rng.uniform(0.6, 1.3)
        tip = ppts[vertex] + reach * d
        mid = (ppts[vertex] + tip) / 2 + np.array([0.0, 0.0, 0.1 * reach])  # a slight arch
        pts = bezier(ppts[vertex], mid, tip, 8)
        base = 0.45 * branches[parent].radii[vertex]
        branches.append(Branch(pts, _taper(base, 0.5, 8), parent, vertex, Level.SECONDARY))
        head = (tip - mid) / np.linalg.norm(tip - mid)
        radii = rng.uniform(0.35, 0.6, 3) * np.array([1, 1, 0.8])
        lobes.append(ellipsoid_lobe(rng, tip + head * radii.min() * 0.6, radii, len(branches) - 1))
    return HBL(trunk[0], tuple(branches), tuple(lobes))
