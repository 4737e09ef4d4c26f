"""Leaf clusters of the levels of detail: one card per lobe at the coarsest level wherever the lobe
stands, and the server's export job reports the cards it wrote."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.skeleton import Leaves
from arboretum_server.grow.tree import grow_tree
from arboretum_server.mesh.lod import MAX_LEVEL, LodOptions, cluster_leaves
from arboretum_server.mesh.scene import tree_mesh


def _cards(centres: np.ndarray, lobe: np.ndarray) -> Leaves:
    k = len(centres)
    normals = np.tile([0.0, 0.0, 1.0], (k, 1))
    axes = np.tile([1.0, 0.0, 0.0], (k, 1))
    return Leaves(centres, normals, axes, np.full(k, 0.01), lobe)


def test_lobes_straddling_the_axes_make_one_cluster_each():
    rng = np.random.default_rng(0)
    centres = np.r_[rng.uniform(-0.1, 0.1, (200, 3)), rng.uniform(-0.1, 0.1, (200, 3)) + [0.0, 0.5, 0.0]]
    lobe = np.repeat([0, 1], 200)
    merged = cluster_leaves(_cards(centres, lobe), 10.0)
    assert len(merged.sizes) == 2
    np.testing.assert_array_equal(merged.lobe, [0, 1])
    np.testing.assert_allclose(merged.centres, [centres[:200].mean(0), centres[200:].mean(0)], atol=1e-12)
    np.testing.assert_allclose(merged.sizes, 0.01 * np.sqrt(200))


def test_clusters_do_not_depend_on_where_the_tree_stands():
    rng = np.random.default_rng(1)
    centres = rng.uniform(-0.5, 0.5, (600, 3))
    lobe = rng.integers(0, 4, 600)
    near = cluster_leaves(_cards(centres, lobe), 0.3)
    for off in ([0.37, -0.21, 0.0], [500000.0, 5400000.0, 0.0]):
        far = cluster_leaves(_cards(centres + off, lobe), 0.3)
        assert len(far.sizes) == len(near.sizes)
        np.testing.assert_allclose(far.centres - off, near.centres, atol=1e-6)


@pytest.fixture(scope="module")
def grown():
    return grow_tree(demo_hbl(np.random.default_rng(3), n_lobes=8), GrowOptions(), np.random.default_rng(2))


def test_coarsest_level_has_one_leaf_card_per_lobe(grown):
    lobes = len(np.unique(grown.leaves.lobe))
    assert lobes == 8 and len(grown.leaves.sizes) > 300
    mesh = tree_mesh(grown, LodOptions(level=MAX_LEVEL))
    assert len(mesh.leaves.faces) // 2 == lobes


def test_server_export_reports_the_cards_it_wrote(tmp_path):
    from arboretum_library.export.gltf_read import parse_glb
    from arboretum_server.service.handlers.export import export_mesh_job

    hbl = demo_hbl(np.random.default_rng(3), n_lobes=4)
    out = export_mesh_job(lambda *a: None, hbl, "glb", 2, 2, {})
    (leaves,) = [m for m in parse_glb(out["data"].tobytes()) if m.name == "leaves"]
    tree = grow_tree(hbl, GrowOptions(), np.random.default_rng(2))
    assert out["stats"]["leaves"] == len(leaves.faces) // 2
    assert out["stats"]["leaves"] < len(tree.leaves.sizes)  # LOD 2 merged cards
    assert out["stats"]["twig_nodes"] == tree.twig_count
