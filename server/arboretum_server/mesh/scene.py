"""A grown tree as export-ready parts: bark tubes and leaf cards with their textured materials."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.assets import asset_path
from arboretum_library.export.parts import Material, MeshPart
from arboretum_library.truth import TreeTruth
from arboretum_server.grow.skeleton import GrownTree, Leaves

from .cards import card_mesh
from .chains import split_chains
from .lod import LodOptions, cluster_leaves, thin_chains
from .tubes import Tubes, sweep

BARK, LEAF = 0, 1
"""Material indices of ``tree_materials``."""


@dataclass(frozen=True, eq=False)
class TreeMesh:
    """The meshes of one tree at one level of detail."""

    bark: MeshPart
    leaves: MeshPart
    tubes: Tubes
    """The bark tubes with their per-face chain (for per-branch checks)."""

    @property
    def parts(self) -> list[MeshPart]:
        return [self.bark, self.leaves]

    @property
    def triangles(self) -> int:
        return int(len(self.bark.faces) + len(self.leaves.faces))

    @property
    def cards(self) -> int:
        """Leaf cards in ``leaves`` (2 triangles each, ``cards.card_mesh``; clustered above LOD 0)."""
        return len(self.leaves.faces) // 2


def tree_materials(textures: bool = True) -> list[Material]:
    """Bark (opaque, tiled texture) and leaves (alpha-masked, double-sided) from ``assets/textures``."""
    bark = asset_path("textures", "bark.png").read_bytes() if textures else None
    leaf = asset_path("textures", "leaf.png").read_bytes() if textures else None
    return [
        Material("bark", (1.0, 1.0, 1.0, 1.0) if textures else (0.35, 0.25, 0.17, 1.0), bark, "bark.png"),
        Material("leaf", (1.0, 1.0, 1.0, 1.0) if textures else (0.2, 0.5, 0.15, 1.0), leaf, "leaf.png",
                 alpha_cutoff=0.5 if textures else None, double_sided=True, roughness=0.7),
    ]


def tree_mesh(tree: GrownTree, lod: LodOptions = LodOptions()) -> TreeMesh:
    """Tubes around every chain of ``tree`` and its leaf cards, at ``lod``."""
    return skeleton_mesh(tree.positions, tree.parents, tree.radii, tree.leaves, lod)


def truth_mesh(truth: TreeTruth, lod: LodOptions = LodOptions()) -> TreeMesh:
    """The mesh of a synthetic tree's ground truth: tubes around its skeleton, a card per leaf.

    A leaf's quaternion turns the card frame to the world (``truth`` module docs): card +X (stem to
    tip) gives the card's axis, card +Z its normal.
    """
    w, x, y, z = np.asarray(truth.leaf_wxyz, dtype=np.float64).reshape(-1, 4).T
    axes = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], axis=1)
    normals = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)
    leaves = Leaves(np.asarray(truth.leaf_positions, np.float64), normals, axes,
                    np.asarray(truth.leaf_sizes, np.float64), np.zeros(len(w), np.int64))
    return skeleton_mesh(truth.positions, truth.parent, truth.radii, leaves, lod)


def skeleton_mesh(positions: np.ndarray, parents: np.ndarray, radii: np.ndarray, leaves: Leaves,
                  lod: LodOptions = LodOptions()) -> TreeMesh:
    """Tubes around every chain of a skeleton (``positions`` (N, 3), ``parents`` (N,), ``radii`` (N,))
    and ``leaves`` as cards, at ``lod``."""
    chains = thin_chains(split_chains(parents, radii), lod.chain_stride)
    tubes = sweep(positions, radii, chains, lod.tube_sides)
    bark = MeshPart("bark", tubes.positions, tubes.faces, tubes.normals, tubes.uv, BARK)
    if lod.level > 0 and len(leaves.sizes):
        leaves = cluster_leaves(leaves, float(np.median(leaves.sizes)) * (1 << lod.level))
    cards = card_mesh(leaves.centres, leaves.normals, leaves.axes, leaves.sizes, "leaves", LEAF)
    return TreeMesh(bark, cards, tubes)
