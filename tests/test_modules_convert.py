"""Converting a grown tree into K module types: pieces, signatures, fits, fidelity and compression."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.geometry import axis_angle_matrix
from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.tree import grow_tree
from arboretum_server.modules.convert import (
    ConvertOptions,
    convert_tree,
    cut_pieces,
    fit_pinned,
    signatures,
)
from arboretum_server.modules.export import flat_size, from_converted, write_instances
from test_export_gltf import validate


@pytest.fixture(scope="module")
def tree():
    return grow_tree(demo_hbl(np.random.default_rng(0), n_lobes=12), GrowOptions(), np.random.default_rng(0))


@pytest.fixture(scope="module")
def converted(tree):
    return {k: convert_tree(tree, ConvertOptions(types=k), np.random.default_rng(3)) for k in (2, 4, 16)}


def test_pieces_partition_the_edges(tree):
    pieces = cut_pieces(tree.parents, tree.radii, 6)
    children = np.concatenate([p[1:] for p in pieces])
    assert np.array_equal(np.sort(children), np.arange(1, len(tree.positions)))  # every edge once
    for p in pieces:
        assert np.array_equal(tree.parents[p[1:]], p[:-1])  # a path down the tree
        assert 1 <= len(p) - 1 <= 9  # at most piece_edges + a joined remainder under half of it


def test_fit_recovers_a_known_similarity():
    rng = np.random.default_rng(0)
    src = np.cumsum(rng.normal(size=(50, 8, 3)), axis=1)
    src -= src[:, :1]
    R = np.stack([axis_angle_matrix(rng.normal(size=3), a) for a in rng.uniform(0, np.pi, 50)])
    s = rng.uniform(0.3, 3.0, 50)
    dst = np.einsum("pij,psj->psi", R, src) * s[:, None, None] + rng.normal(size=(50, 1, 3))
    R_fit, s_fit = fit_pinned(src, dst)
    np.testing.assert_allclose(R_fit, R, atol=1e-9)
    np.testing.assert_allclose(s_fit, s, rtol=1e-9)
    assert np.allclose(np.linalg.det(R_fit), 1.0)


def test_signatures_ignore_rotation_translation_and_scale(tree):
    pieces = cut_pieces(tree.parents, tree.radii, 6)[:40]
    P = np.stack([tree.positions[p][[0, -1]] for p in pieces])  # straight two-point pieces
    P = np.stack([np.linspace(a, b, 8) for a, b in P]) + np.random.default_rng(1).normal(0, 0.01, (40, 8, 3))
    r = np.linspace(0.05, 0.01, 8)[None].repeat(40, 0)
    length = np.linalg.norm(np.diff(P, axis=1), axis=2).sum(1)
    R = axis_angle_matrix([1.0, 2.0, 0.5], 1.1)
    Q = 2.5 * P @ R.T + [3.0, -1.0, 7.0]
    np.testing.assert_allclose(signatures(Q, 2.5 * r, 2.5 * length, 4.0), signatures(P, r, length, 4.0),
                               atol=1e-9)


def test_instances_rebuild_the_pieces(tree, converted):
    conv = converted[16]
    pieces = cut_pieces(tree.parents, tree.radii, 6)
    assert len(conv.module) == len(pieces) and len(conv.meshes) == 16
    starts = np.stack([tree.positions[p[0]] for p in pieces])
    np.testing.assert_allclose(conv.T_world_module[:, :3, 3], starts, atol=1e-12)  # bases pinned
    ends = np.stack([tree.positions[p[-1]] for p in pieces])
    tips = np.einsum("pij,pj->pi", conv.T_world_module[:, :3, :3], conv.skeletons[conv.module, -1])
    tips += starts
    height = conv.height
    assert np.median(np.linalg.norm(tips - ends, axis=1)) < 0.005 * height
    assert conv.parent[0] == -1 and (conv.parent[1:] >= 0).all() and (conv.parent[1:] < len(pieces)).all()


def test_chamfer_shrinks_as_types_grow(converted):
    c2, c4, c16 = converted[2].chamfer_fraction, converted[4].chamfer_fraction, converted[16].chamfer_fraction
    assert c16 < c2 and c16 <= c4 * 1.05
    assert c16 < 0.001  # K = 16: under 0.1 % of the tree's height
    assert c2 < 0.003  # K = 2: under 0.3 %


def test_compression_improves_as_types_shrink(tmp_path, converted):
    ratios = {}
    for k, conv in converted.items():
        inst = from_converted(conv)
        size = write_instances(tmp_path / f"k{k}.glb", inst)
        ratios[k] = flat_size(inst, ".glb") / size
        assert validate(tmp_path / f"k{k}.glb")["issues"]["numErrors"] == 0
    assert ratios[2] > ratios[4] > ratios[16] > 5


def test_same_seed_same_conversion(tmp_path, tree):
    a, b = (convert_tree(tree, ConvertOptions(types=8), np.random.default_rng(5)) for _ in range(2))
    np.testing.assert_array_equal(a.T_world_module, b.T_world_module)
    write_instances(tmp_path / "a.usdc", from_converted(a))
    write_instances(tmp_path / "b.usdc", from_converted(b))
    assert (tmp_path / "a.usdc").read_bytes() == (tmp_path / "b.usdc").read_bytes()
