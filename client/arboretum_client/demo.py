"""Small, deterministic HBL examples for the offline client (``FakeSession``), tests and docs.

Each example is a main branch rising from the origin with secondary branches ending in lobes
(octahedral hulls around leaf points), like the library's examples but made from a seed, not a scan.
"""

from __future__ import annotations

import numpy as np

from arboretum_library.descriptors import describe, tags_for
from arboretum_library.model import HBL, LEAF, WOOD, Branch, Example, Level, Lobe, Provenance

OCTA_DIRS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTA_FACES = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]],
                      np.int32)
"""Outward-facing triangles of the unit octahedron."""


def octa_lobe(points: np.ndarray, centre: np.ndarray, radius: float, branch: int) -> Lobe:
    """A lobe around ``centre`` with an octahedral hull of ``radius`` enclosing ``points`` (M, 3)."""
    centre = np.asarray(centre, np.float64)
    return Lobe(np.asarray(points, np.float64).reshape(-1, 3), centre + OCTA_DIRS * radius, OCTA_FACES,
                centre, branch)


def _main_axis(rng: np.random.Generator, length: float, curved: bool, n: int = 9) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)
    lean = rng.uniform(0.15, 0.45) if curved else 0.03
    heading = rng.uniform(0, 2 * np.pi)
    out = lean * length * s**2
    return np.c_[out * np.cos(heading), out * np.sin(heading), s * length]


def demo_structure(rng: np.random.Generator, n_lobes: int = 4, curved: bool = False,
                   length: float = 1.5, n_points: int = 240) -> HBL:
    """An HBL: one main branch, ``n_lobes`` secondary branches with a lobe each, wood and leaf points."""
    axis = _main_axis(rng, length, curved)
    branches = [Branch(axis, np.linspace(0.04, 0.012, len(axis)))]
    lobes, leaf_pts = [], []
    per_lobe = max(n_points * 2 // 3 // max(n_lobes, 1), 1)
    for k in range(n_lobes):
        vertex = 3 + (k * 2) % (len(axis) - 4)
        angle = 2 * np.pi * k / max(n_lobes, 1) + rng.uniform(-0.3, 0.3)
        start = axis[vertex]
        tip = start + rng.uniform(0.3, 0.45) * np.array([np.cos(angle), np.sin(angle), 0.45])
        pts = start + np.linspace(0, 1, 4)[:, None] * (tip - start)
        branches.append(Branch(pts, np.linspace(0.015, 0.005, 4), 0, vertex, Level.SECONDARY))
        radius = rng.uniform(0.1, 0.16)
        dirs = rng.normal(size=(per_lobe, 3))
        dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-9)
        members = tip + dirs * radius * rng.uniform(0.1, 0.55, (per_lobe, 1))
        leaf_pts.append(members)
        lobes.append(octa_lobe(members, tip, radius * 1.8, len(branches) - 1))
    verts = np.concatenate([b.points for b in branches])
    n_wood = max(n_points - per_lobe * n_lobes, 1)
    wood = verts[rng.integers(0, len(verts), n_wood)] + rng.normal(0, 0.01, (n_wood, 3))
    points = np.concatenate([wood, *leaf_pts]) if leaf_pts else wood
    labels = np.r_[np.full(len(wood), WOOD), np.full(len(points) - len(wood), LEAF)].astype(np.uint8)
    return HBL(axis[0], tuple(branches), tuple(lobes), points, labels)


def demo_example(example_id: str, seed: int, n_lobes: int = 4, curved: bool = False,
                 species: str = "demo") -> Example:
    """One example from ``seed`` (same seed, same example); tags from the library's descriptors."""
    structure = demo_structure(np.random.default_rng(seed), n_lobes, curved)
    d = describe(structure)
    prov = Provenance(f"demo-{seed}", f"{seed:064x}", species, {"seed": seed})
    return Example(example_id, structure, prov, d, tags_for(d))


def demo_library() -> dict[str, Example]:
    """Six examples: straight and curved, two to six lobes, two 'species'."""
    specs = [("oak-0001", 1, 4, False, "oak"), ("oak-0002", 2, 6, True, "oak"),
             ("oak-0003", 3, 3, False, "oak"), ("pine-0001", 4, 2, False, "pine"),
             ("pine-0002", 5, 5, True, "pine"), ("pine-0003", 6, 3, True, "pine")]
    return {i: demo_example(i, s, n, c, sp) for i, s, n, c, sp in specs}


def demo_tree(seed: int = 7, n_main: int = 3, n_lobes: int = 8) -> HBL:
    """A whole-tree draft (several main branches) for the refinement mode."""
    rng = np.random.default_rng(seed)
    parts = [demo_structure(rng, n_lobes // n_main + 1, k > 0, 2.2 if k == 0 else 1.2) for k in range(n_main)]
    branches, lobes, pts, labels = [], [], [], []
    trunk = parts[0].branches[0].points
    for k, part in enumerate(parts):
        off = np.zeros(3) if k == 0 else trunk[3 + 2 * k] - part.root
        base = len(branches)
        for b in part.branches:
            parent = b.parent + base if b.parent >= 0 else (0 if k else -1)
            vertex = b.parent_vertex if b.parent >= 0 else (3 + 2 * k if k else -1)
            branches.append(Branch(b.points + off, b.radii, parent, vertex, b.level))
        lobes += [octa_lobe(lb.points + off, lb.centre + off, float(np.ptp(lb.hull_vertices[:, 0])) / 2,
                            lb.branch + base) for lb in part.lobes]
        pts.append(part.points + off)
        labels.append(part.labels)
    return HBL(trunk[0], tuple(branches), tuple(lobes), np.concatenate(pts), np.concatenate(labels))
