"""Instanced export of modular trees: write time and file sizes, instanced against a flat mesh.

Scenes: ~100 instances (default modules in a 4 m tetrahedron crown), ~2,000 (sphere r = 8 m, trunk x2,
d_k = 1/20, as in bench_modules), ~4,000 (a grown demo tree converted into 16 types), and the ~2,000 tree
again with every module subdivided twice (16x triangles), and the ~4,000 tree with module tubes of 16 sides x
24 rings (module meshes about as detailed as the paper's, whose trees of up to 4,600 modules store 1 MB
instanced against 110 MB as meshes, 1:110). Baseline: writing the same tree as one flat
GLB. Plus conversion of a ~20k-node grown tree into 16 types. Sizes are exact; times are provisional (two
cores shared with other jobs).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from bench.harness import Row, median_time


def _grown(crowns, T0, kill, subdivide=0):
    from arboretum_library.assets import asset_path
    from arboretum_server.modules.crown import crown_from_meshes
    from arboretum_server.modules.export import from_modular_tree
    from arboretum_server.modules.grow import grow_modular_tree
    from arboretum_server.modules.moduleset import load_module_set
    from arboretum_server.modules.options import ModularTreeOptions

    modules = load_module_set(asset_path("modules", "default"))
    o = ModularTreeOptions(kill_fraction=kill)
    tree = grow_modular_tree(modules, crown_from_meshes(crowns), o, np.random.default_rng(1), T_world_trunk=T0)
    inst = from_modular_tree(tree, modules)
    return _subdivided(inst, subdivide) if subdivide else inst


def _subdivided(inst, times: int):
    import dataclasses

    import trimesh

    from arboretum_library.export.parts import MeshPart
    from arboretum_server.modules.export import vertex_normals

    parts = []
    for m in inst.meshes:
        v, f = m.positions, m.faces
        for _ in range(times):
            v, f = trimesh.remesh.subdivide(v, f)
        parts.append(MeshPart(m.name, v, f, vertex_normals(v, f)))
    return dataclasses.replace(inst, meshes=tuple(parts))


def _converted(density: float = 1.0):
    from arboretum_server.grow.demo import demo_hbl
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree

    return grow_tree(demo_hbl(np.random.default_rng(0)), GrowOptions(density=density), np.random.default_rng(0))


def _scenes():
    from arboretum_library.geometry import make_transform
    from arboretum_server.modules.convert import ConvertOptions, convert_tree
    from arboretum_server.modules.export import from_converted
    from arboretum_server.modules.shapes import sphere_mesh, tetrahedron_mesh

    large = ([sphere_mesh([0, 0, 11], 8)], make_transform(scale=2.0), 0.05)
    grown = _converted()
    conv = convert_tree(grown, ConvertOptions(types=16), np.random.default_rng(0))
    detailed = convert_tree(grown, ConvertOptions(types=16, sides=16, rings=24), np.random.default_rng(0))
    return {
        "~100 (tetrahedron crown)": _grown([tetrahedron_mesh([0, 0, 3.8], 4.0)], None, 0.08),
        "~2,000 (sphere crown)": _grown(*large),
        "~4,000 (converted demo tree, K=16)": from_converted(conv),
        "~2,000, modules x16 triangles": _grown(*large, subdivide=2),
        "~4,000 converted, modules 16 sides x 24 rings": from_converted(detailed),
    }


def _export_rows(name: str, inst, folder: Path) -> list[Row]:
    from arboretum_library.export.gltf import write_glb
    from arboretum_server.modules.export import BARK, flat_part, write_instances

    rows = []
    flat = flat_part(inst)
    t_flat = median_time(lambda: write_glb(folder / "flat.glb", [flat], [BARK]), runs=3)
    flat_glb = (folder / "flat.glb").stat().st_size
    for label, suffix, plain in (("GLB EXT_mesh_gpu_instancing", ".glb", False),
                                 ("GLB plain nodes", ".glb", True), ("USDC PointInstancer", ".usdc", False)):
        path = folder / f"out{suffix}"
        t = median_time(lambda p=path, pl=plain: write_instances(p, inst, pl), runs=3)
        size = path.stat().st_size
        flat_size = flat_glb
        if suffix == ".usdc":
            from arboretum_server.modules.export import flat_size as measure

            flat_size = measure(inst, ".usdc")
        rows.append(Row(f"export {name}: {label}", t, "s", runs=3, baseline="flat GLB write",
                        ratio=t / t_flat, note=f"{len(inst.module)} instances, {inst.triangles} triangles",
                        extra={"bytes": size, "flat_bytes": flat_size, "compression": flat_size / size,
                               "instances": int(len(inst.module)), "types": len(inst.meshes)}))
    return rows


def _conversion_row() -> Row:
    from arboretum_server.modules.convert import ConvertOptions, convert_tree

    tree = _converted(density=2.0)
    times, conv = [], None
    for seed in range(3):
        t0 = time.perf_counter()
        conv = convert_tree(tree, ConvertOptions(types=16), np.random.default_rng(seed))
        times.append(time.perf_counter() - t0)
    return Row(f"convert a {len(tree.positions)}-node grown tree into 16 types", float(np.median(times)),
               "s", runs=3, note=f"{len(conv.module)} pieces, Chamfer {100 * conv.chamfer_fraction:.3f}% of height",
               extra={"nodes": int(len(tree.positions)), "pieces": int(len(conv.module)),
                      "chamfer_fraction": conv.chamfer_fraction})


def _fidelity_rows() -> list[Row]:
    """Chamfer (fraction of height) and GLB compression against K on the demo tree."""
    from arboretum_server.modules.convert import ConvertOptions, convert_tree
    from arboretum_server.modules.export import flat_size, from_converted, write_instances

    tree = _converted()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in (1, 2, 4, 8, 16, 32, 64):
            conv = convert_tree(tree, ConvertOptions(types=k), np.random.default_rng(0))
            inst = from_converted(conv)
            size = write_instances(Path(tmp) / "t.glb", inst)
            rows.append(Row(f"convert demo tree K={k}: Chamfer / height", conv.chamfer_fraction, "fraction",
                            extra={"bytes": size, "flat_bytes": flat_size(inst, ".glb"),
                                   "compression": flat_size(inst, ".glb") / size, "pieces": len(conv.module)}))
    return rows


def run() -> list[Row]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-modules-export-") as tmp:
        for name, inst in _scenes().items():
            rows += _export_rows(name, inst, Path(tmp))
    rows.append(_conversion_row())
    return rows + _fidelity_rows()
