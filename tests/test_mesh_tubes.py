"""Branch tubes: one closed, consistently oriented tube per chain; chains cover the graph; LOD."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.radii import pipe_radii
from arboretum_server.grow.tree import grow_tree
from arboretum_server.mesh.chains import split_chains
from arboretum_server.mesh.lod import LodOptions, cluster_leaves
from arboretum_server.mesh.scene import tree_mesh
from arboretum_server.mesh.tubes import sweep
from factories import make_hbl


@pytest.fixture(scope="module")
def tree():
    return grow_tree(make_hbl(np.random.default_rng(2), n_main=3, n_lobes=4), GrowOptions(),
                     np.random.default_rng(0))


def weld(tubes, sides: int, faces: np.ndarray) -> np.ndarray:
    """Faces with each ring's seam vertex (u = 1) replaced by its first vertex (u = 0): topology only."""
    ring = len(tubes.positions) - 2 * int(tubes.face_chain.max() + 1)  # ring vertices come first
    v = np.arange(len(tubes.positions))
    seam = (v < ring) & (v % (sides + 1) == sides)
    v[seam] -= sides
    assert np.allclose(tubes.positions[seam], tubes.positions[v[seam]])
    return v[faces]


def edge_check(faces: np.ndarray) -> tuple[bool, bool]:
    """(every undirected edge in exactly 2 faces, every directed edge used once = consistent winding)."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected = np.sort(directed, axis=1)
    _, counts = np.unique(undirected, axis=0, return_counts=True)
    _, dcounts = np.unique(directed, axis=0, return_counts=True)
    return bool((counts == 2).all()), bool((dcounts == 1).all())


def test_every_branch_tube_is_watertight(tree):
    chains = split_chains(tree.parents, tree.radii)
    tubes = sweep(tree.positions, tree.radii, chains, 7)
    n_chains = len(chains.starts) - 1
    assert n_chains > 50
    for c in range(n_chains):
        f = weld(tubes, 7, tubes.faces[tubes.face_chain == c])
        manifold, oriented = edge_check(f)
        assert manifold and oriented, c
        if c % 10 == 0:  # an independent check on a sample of the tubes
            m = trimesh.Trimesh(tubes.positions, tubes.faces[tubes.face_chain == c], process=True)
            assert m.is_watertight and m.is_winding_consistent and m.volume > 0, c


def test_tube_volume_matches_cylinder():
    pts = np.c_[np.zeros(5), np.zeros(5), np.linspace(0, 2, 5)]
    parents = np.arange(-1, 4)
    tubes = sweep(pts, np.full(5, 0.1), split_chains(parents, np.full(5, 0.1)), 64)
    m = trimesh.Trimesh(tubes.positions, tubes.faces, process=True)
    assert m.volume == pytest.approx(np.pi * 0.01 * 2, rel=0.01)
    assert np.allclose(np.linalg.norm(tubes.normals, axis=1), 1.0)
    side = tubes.uv[: 5 * 65]
    assert side[:, 0].min() == 0 and side[:, 0].max() == 1
    assert side[-1, 1] == pytest.approx(2 / (2 * np.pi * 0.1))  # v: one repeat per circumference


def test_frames_follow_a_bent_chain_without_twist():
    """A quarter circle: ring normals stay perpendicular to the tangent (parallel transport)."""
    s = np.linspace(0, np.pi / 2, 20)
    pts = np.c_[np.sin(s), np.zeros(20), 1 - np.cos(s)]
    parents = np.arange(-1, 19)
    ch = split_chains(parents, np.ones(20))
    tubes = sweep(pts, np.full(20, 0.05), ch, 8)
    ring = tubes.positions[: 20 * 9].reshape(20, 9, 3)
    centre = ring[:, :8].mean(1)
    assert np.allclose(centre, pts, atol=1e-9)
    radial = ring[:, 0] - pts
    tang = np.gradient(pts, axis=0)
    assert np.abs((radial * tang).sum(1) / np.linalg.norm(tang, axis=1)).max() < 5e-3
    # rotation-minimising: the first ring vector keeps its y-component (no twist about the tangent)
    assert np.ptp(radial[:, 1]) < 1e-6


def test_chains_cover_every_edge_once(tree):
    ch = split_chains(tree.parents, tree.radii)
    same = ch.chain[1:] == ch.chain[:-1]
    a, b = ch.nodes[:-1][same], ch.nodes[1:][same]
    assert (tree.parents[b] == a).all()
    assert len(b) == int((tree.parents >= 0).sum()) and len(np.unique(b)) == len(b)


def test_lod_reduces_triangles_and_clusters_leaves(tree):
    full = tree_mesh(tree, LodOptions(sides=8, level=0))
    low = tree_mesh(tree, LodOptions(sides=8, level=1))
    lower = tree_mesh(tree, LodOptions(sides=8, level=2))
    assert full.triangles > low.triangles > lower.triangles
    assert len(low.leaves.faces) < 0.7 * len(full.leaves.faces)
    merged = cluster_leaves(tree.leaves, 10.0)
    assert len(merged.sizes) <= len(np.unique(tree.leaves.lobe)) * 8
    total_area = (tree.leaves.sizes**2).sum()
    assert (merged.sizes**2).sum() == pytest.approx(total_area, rel=0.5)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 60), st.integers(3, 12))
def test_random_trees_give_watertight_tubes(seed, n, sides):
    """Property: any tree (random forks, random turns, even reversals) sweeps to closed tubes."""
    rng = np.random.default_rng(seed)
    parents = np.r_[-1, [rng.integers(0, i) for i in range(1, n)]]
    pos = np.zeros((n, 3))
    for i in range(1, n):
        d = rng.normal(size=3)
        pos[i] = pos[parents[i]] + rng.uniform(0.2, 1.0) * d / np.linalg.norm(d)
    if n > 2 and parents[2] == 1:
        pos[2] = pos[0]  # an exact hairpin: 0 -> 1 -> back to 0
    radii = pipe_radii(parents, np.full(n, 0.02))
    chains = split_chains(parents, radii)
    tubes = sweep(pos, radii, chains, sides)
    assert np.isfinite(tubes.positions).all()
    for c in range(len(chains.starts) - 1):
        manifold, oriented = edge_check(weld(tubes, sides, tubes.faces[tubes.face_chain == c]))
        assert manifold and oriented


def test_ring_at_a_right_angle_lies_on_both_cylinders():
    """Miter: the ring at a 90° turn is where the incoming and outgoing tubes meet (no pinch)."""
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]])
    r = 0.1
    tubes = sweep(pts, np.full(3, r), split_chains(np.array([-1, 0, 1]), np.ones(3)), 16)
    corner = tubes.positions[17:34]
    assert np.allclose(np.hypot(corner[:, 1], corner[:, 2]), r, atol=1e-12)  # around the x axis
    assert np.allclose(np.hypot(corner[:, 0] - 1, corner[:, 2]), r, atol=1e-12)  # around x = 1
    assert np.linalg.norm(corner - pts[1], axis=1).max() == pytest.approx(r * np.sqrt(2))
    assert np.allclose(np.linalg.norm(tubes.normals, axis=1), 1.0)


def test_frames_do_not_twist_at_sharp_zigzag_turns():
    """A planar zigzag with 150° turns: the frame's binormal stays the plane's normal (one sign)."""
    n, sides = 12, 8
    pts = np.c_[np.arange(n) * 0.3, np.where(np.arange(n) % 2, 1.0, 0.0), np.zeros(n)]
    tubes = sweep(pts, np.full(n, 0.05), split_chains(np.arange(-1, n - 1), np.ones(n)), sides)
    ring = tubes.positions[: n * (sides + 1)].reshape(n, sides + 1, 3)
    quarter = ring[:, sides // 4] - pts  # the ring vector at 90°: along the binormal, never stretched
    assert np.allclose(quarter[:, :2], 0.0, atol=1e-12)
    assert np.allclose(quarter[:, 2], quarter[0, 2]) and abs(quarter[0, 2]) == pytest.approx(0.05)
    assert np.isfinite(tubes.positions).all()
