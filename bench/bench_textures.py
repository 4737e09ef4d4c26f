"""Textured vs flat rendering of one grown tree (the same GLB, the same process, the same camera).

Run by ``make bench`` (``python -m bench textures``).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from bench.harness import Row, median_time

SIZE = (1280, 720)


def _tree_glb(folder: Path) -> Path:
    from arboretum_library.export.gltf import write_glb
    from arboretum_server.grow.demo import demo_hbl
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.scene import tree_materials, tree_mesh

    tree = grow_tree(demo_hbl(np.random.default_rng(0)), GrowOptions(density=1.0), np.random.default_rng(7))
    path = folder / "tree.glb"
    write_glb(path, tree_mesh(tree).parts, tree_materials())
    return path


def run() -> list[Row]:
    from arboretum_client.camera import fit_camera
    from arboretum_client.headless import OffscreenRenderer
    from arboretum_client.render.textures import coverage_mipmaps
    from arboretum_client.render_cli import load_scene
    from arboretum_client.scene import Scene
    from arboretum_client.scene_build import HBLStyle

    rows = []
    with tempfile.TemporaryDirectory() as tmp, OffscreenRenderer(SIZE) as off:
        path = _tree_glb(Path(tmp))
        scenes = {t: load_scene(path, HBLStyle(), t) for t in (False, True)}
        cam = fit_camera(scenes[True].bounds(), "iso", SIZE[0] / SIZE[1])
        default = off.renderer.textures.anisotropy
        tris = sum(len(it.faces) for it in scenes[True].items)
        times = {}
        for key, scene, aniso in (("flat", scenes[False], 1.0), ("textured", scenes[True], None),
                                  ("textured, 16x anisotropic", scenes[True], 16.0)):
            off.render(Scene(), cam)  # frees the cached textures, so the anisotropy below applies
            off.renderer.textures.anisotropy = default if aniso is None else aniso
            off.render(scene, cam)  # upload + warm-up
            times[key] = median_time(lambda scene=scene: off.render(scene, cam), runs=9, warmup=2)
        rows.append(Row(f"frame, flat materials ({tris:,} triangles, {SIZE[0]}x{SIZE[1]})", times["flat"] * 1e3,
                        "ms", runs=9))
        for key in ("textured", "textured, 16x anisotropic"):
            rows.append(Row(f"frame, {key} (bark + cut-out leaves)", times[key] * 1e3, "ms", runs=9,
                            baseline="flat frame", ratio=times[key] / times["flat"]))
        leaf = next(it.texture for it in scenes[True].items if it.alpha_cutoff > 0)
        t = median_time(lambda: coverage_mipmaps(leaf, 0.5), runs=9)
        rows.append(Row(f"coverage mipmaps of the leaf texture {leaf.shape[1]}x{leaf.shape[0]} (CPU, once)",
                        t * 1e3, "ms", runs=9))
    return rows


