"""Regenerate the pictures of Arboretum's docs (docs/img/{concept,gallery,decomp,growth,modules}_*.png).

    .venv/bin/python docs/pictures.py                 # every section
    .venv/bin/python docs/pictures.py synthetic growth  # only these sections

Sections: concepts, synthetic, decomposition, main-fit, several-trees, growth, modules. Every picture is rendered headless
(EGL, Mesa llvmpipe) by arboretum_client's renderer from data this script makes with fixed seeds, so the
same command gives the same pictures. Each file written is printed. Decompositions run the real command,
``arboretum decompose SCAN --library TMP --save-hbl TMP.npz``, in a temporary folder.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from arboretum_client.camera import VIEWS, Camera
from arboretum_client.headless import OffscreenRenderer
from arboretum_client.scene import InstancedMesh, Mesh, PointSet, Polyline, Scene, grid_for_bounds
from arboretum_client.scene_build import LEAF_COLOR, WOOD_COLOR, HBLStyle, hbl_items
from arboretum_library.codec import load_record
from arboretum_library.model import HBL, LEAF
from arboretum_library.pointio import read_points
from arboretum_library.truth import TreeTruth, branch_polylines, leaf_card_corners, load_truth

ROOT = Path(__file__).resolve().parent.parent
IMG = ROOT / "docs" / "img"
SYNTH = ROOT / "assets" / "synth"
SCANS = ROOT / "assets" / "scans"
BARK_RGB = (0.42, 0.30, 0.19)
FOLIAGE_RGB = (0.30, 0.58, 0.22)
FAINT_RGB = (0.45, 0.47, 0.52)
MAX_BYTES = 250_000

# ---------------------------------------------------------------- rendering and image helpers


def frame(bounds: np.ndarray, aspect: float, azimuth: float = -60.0, elevation: float = 12.0,
          margin: float = 1.1, fov_y: float = 35.0, points: np.ndarray | None = None) -> Camera:
    """The nearest camera at (azimuth, elevation) that sees all of ``points`` (N, 3) (default: the 8
    corners of ``bounds`` (2, 3)), aimed at the middle of their extent across the view."""
    lo, hi = np.asarray(bounds, np.float64)
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    pts = (np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
           if points is None else np.asarray(points, np.float64))
    cam = Camera(target=tuple((lo + hi) / 2), distance=1.0, azimuth=azimuth, elevation=elevation, fov_y=fov_y)
    R = cam.view_matrix()[:3, :3]
    c = (pts - np.asarray(cam.target)) @ R.T
    shift = (c[:, :2].min(axis=0) + c[:, :2].max(axis=0)) / 2  # recentre across the view (x, y)
    cam = replace(cam, target=tuple(np.asarray(cam.target) + R[0] * shift[0] + R[1] * shift[1]))
    c[:, :2] -= shift
    tan_y = math.tan(math.radians(fov_y) / 2)
    need = np.maximum(np.abs(c[:, 0]) / (tan_y * aspect), np.abs(c[:, 1]) / tan_y) + c[:, 2]
    dist = max(float(need.max()) * margin, radius * 0.1)
    return replace(cam, distance=dist, near=max(dist - 2 * radius, dist * 1e-3), far=dist + 3 * radius)


def scene_points(scene: Scene, cap: int = 40_000) -> np.ndarray:
    """(<= cap, 3) float64 sample of every item's points (instanced meshes: all their mesh vertices)."""
    parts = []
    for it in scene.items:
        if isinstance(it, InstancedMesh):
            v = np.c_[it.mesh.vertices, np.ones(len(it.mesh.vertices))]
            parts.append(np.einsum("nij,vj->nvi", it.matrices, v)[..., :3].reshape(-1, 3))
        else:
            parts.append(np.asarray(it.points if hasattr(it, "points") else it.vertices))
    allp = np.concatenate(parts).astype(np.float64)
    step = max(1, len(allp) // cap)
    return allp[::step]


def view_angles(view: str | tuple[float, float]) -> tuple[float, float]:
    """(azimuth, elevation) of a named view or a pair; 'tree': a slightly raised three-quarter view."""
    if isinstance(view, tuple):
        return view
    return VIEWS[view] if view in VIEWS else (-60.0, 8.0)


def render(scene: Scene, size: tuple[int, int], view: str | tuple[float, float] = "tree", camera: Camera | None = None,
           bounds: np.ndarray | None = None) -> Image.Image:
    """An RGB pillow image of ``scene`` from ``view``, framed tightly on its points (or on the
    corners of ``bounds`` when given, so several panels share one scale)."""
    w, h = size
    if camera is None:
        az, el = view_angles(view)
        pts = scene_points(scene) if bounds is None else None
        camera = frame(scene.bounds() if bounds is None else bounds, w / h, az, el, points=pts)
    with OffscreenRenderer(size) as r:
        return Image.fromarray(r.render(scene, camera)[:, :, :3])


def font(px: int) -> ImageFont.ImageFont:
    for name in ("DejaVuSans.ttf", "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(name, px)
        except OSError:
            continue
    return ImageFont.load_default(size=px)


def label(img: Image.Image, text: str, px: int = 18) -> Image.Image:
    """``img`` with ``text`` in dark grey at its top-left corner (multi-line allowed)."""
    box = Image.new("RGBA", img.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(box)
    x0, y0, x1, y1 = draw.multiline_textbbox((10, 8), text, font=font(px), spacing=3)
    draw.rectangle([x0 - 5, y0 - 4, x1 + 5, y1 + 5], fill=(250, 250, 252, 190))  # keeps text readable
    draw.multiline_text((10, 8), text, fill=(30, 30, 35, 255), font=font(px), spacing=3)
    return Image.alpha_composite(img.convert("RGBA"), box).convert("RGB")


def sheet(cells: list[Image.Image], cols: int) -> Image.Image:
    """Cells of equal size laid out row by row, separated by a 2 px light line."""
    w, h = cells[0].size
    rows = -(-len(cells) // cols)
    out = Image.new("RGB", (cols * w, rows * h), (235, 236, 238))
    draw = ImageDraw.Draw(out)
    for k, cell in enumerate(cells):
        x, y = (k % cols) * w, (k // cols) * h
        out.paste(cell, (x, y))
        draw.rectangle([x, y, x + w - 1, y + h - 1], outline=(200, 202, 206), width=2)
    return out


def save(img: Image.Image, name: str) -> Path:
    """Write ``docs/img/name`` atomically; palette-quantised when the RGB PNG would exceed 250 KB."""
    path = IMG / name
    IMG.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{name}.{os.getpid()}.tmp")
    try:
        img.save(tmp, format="PNG", optimize=True)
        for colors in (256, 128, 64):  # fewer colours until it fits
            if tmp.stat().st_size <= MAX_BYTES:
                break
            img.quantize(colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.FLOYDSTEINBERG).save(
                tmp, format="PNG", optimize=True)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    print(f"wrote {path.relative_to(ROOT)} ({img.size[0]}x{img.size[1]}, {path.stat().st_size // 1024} KB)")
    return path


def with_grid(items: list, grid: bool = True) -> Scene:
    scene = Scene(items=tuple(items))
    return replace(scene, grid=grid_for_bounds(scene.bounds())) if grid else scene


def f32(a) -> np.ndarray:
    return np.asarray(a, np.float32)


# ---------------------------------------------------------------- scene items from records


def truth_items(truth: TreeTruth, leaves: str = "quads", min_radius: float = 0.0,
                color=BARK_RGB) -> list:
    """A TreeTruth as bark tubes with its radii (at least ``min_radius``) and leaf cards as green
    quads (``leaves='quads'``), green dots (``'points'``) or nothing (``'none'``)."""
    items = []
    for nodes in branch_polylines(truth):
        if len(nodes) < 2:
            continue
        items.append(Polyline(points=f32(truth.positions[nodes]),
                              radii=f32(np.maximum(truth.radii[nodes], min_radius)), color=f32(color)))
    if leaves == "quads" and truth.leaf_count:
        corners = leaf_card_corners(truth).reshape(-1, 3)
        base = 4 * np.arange(truth.leaf_count)[:, None]
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
        items.append(Mesh(vertices=f32(corners), faces=faces.astype(np.int32), color=f32(FOLIAGE_RGB)))
    elif leaves == "points" and truth.leaf_count:
        items.append(PointSet(points=f32(truth.leaf_positions),
                              colors=f32(np.broadcast_to(FOLIAGE_RGB, truth.leaf_positions.shape)), size_px=2.5))
    return items


def label_points(points: np.ndarray, labels: np.ndarray | None, size_px: float = 2.0) -> PointSet:
    """Points coloured by label: wood brown, leaf green (all wood when unlabelled)."""
    leaf = np.zeros(len(points), bool) if labels is None else labels == LEAF
    return PointSet(points=f32(points), colors=f32(np.where(leaf[:, None], LEAF_COLOR, WOOD_COLOR)), size_px=size_px)


def faint_points(points: np.ndarray, size_px: float = 1.8) -> PointSet:
    return PointSet(points=f32(points), colors=f32(np.broadcast_to(FAINT_RGB, np.shape(points))), size_px=size_px)


def hbl_over_points(hbl: HBL, points: np.ndarray | None = None) -> Scene:
    """The HBL (red main, black secondary branches, translucent lobes) over faint source points."""
    items, _ = hbl_items(hbl, HBLStyle(min_radius_fraction=0.002, lobe_alpha=0.28))
    pts = hbl.points if points is None else points
    return with_grid(([faint_points(pts)] if len(pts) else []) + items)


def truth_min_radius(truth: TreeTruth) -> float:
    ext = truth.positions.max(axis=0) - truth.positions.min(axis=0)
    return 0.0015 * float(np.linalg.norm(ext))


# ---------------------------------------------------------------- decomposition (the real command)


def decompose(scan: Path, workdir: Path, extra: tuple[str, ...] = ()) -> HBL:
    """Run ``arboretum decompose SCAN --library LIB --save-hbl OUT.npz`` and load the HBL."""
    exe = Path(sys.executable).with_name("arboretum")
    out = workdir / f"{scan.stem}_hbl.npz"
    if out.exists():  # already decomposed by an earlier section of this run
        return load_record(out, HBL)
    cmd = [str(exe), "decompose", str(scan), "--library", str(workdir / f"lib_{scan.stem}"),
           "--save-hbl", str(out), *extra]
    env = {**os.environ, "OMP_WAIT_POLICY": "PASSIVE"}
    done = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"decompose failed for {scan}:\n{done.stderr.strip()}")
    return load_record(out, HBL)


def real_scans() -> list[Path]:
    """The bundled real scans 01, 06, 07 and 10 (their main point file each)."""
    out = []
    for d in sorted(SCANS.iterdir()):
        if d.is_dir() and d.name[:2] in ("01", "06", "07", "10"):
            files = sorted(p for p in d.iterdir() if p.suffix in (".xyz", ".txt", ".ply", ".las", ".laz"))
            out.append(next((p for p in files if p.stem == d.name), files[0]))
    return out


# ---------------------------------------------------------------- sections


def section_synthetic(work: Path) -> None:
    """Guiding-vector presets, the 8 harmonic presets, leaf-on/off and missing-sector scans."""
    from arboretum_server.synth.guiding import grow_guiding
    from arboretum_server.synth.harmonic import grow_species
    from arboretum_server.synth.harmonic_presets import SPECIES
    from arboretum_server.synth.presets import preset

    cells = []
    for name, seed in (("default", 1), ("hanging", 2), ("upward", 1), ("helical", 1)):
        asset = SYNTH / f"guiding_{name}_s{seed}_truth.npz"
        truth = load_truth(asset) if asset.exists() else grow_guiding(preset(name), seed, species=name)
        scene = with_grid(truth_items(truth, "points", truth_min_radius(truth)))
        cells.append(label(render(scene, (320, 720)), f"{name} (seed {seed})\n{truth.branch_count:,} branches"))
    save(sheet(cells, 4), "gallery_guiding_presets.png")

    cells = []
    for name in sorted(SPECIES):
        truth = grow_species(name, seed=1)
        scene = with_grid(truth_items(truth, "points", truth_min_radius(truth)))
        h = float(np.ptp(truth.positions[:, 2]))
        cells.append(label(render(scene, (320, 360)), f"{name}  {h:.1f} m", px=16))
    save(sheet(cells, 4), "gallery_harmonic_presets.png")

    panels = []
    for file, text in (("guiding_default_s1.ply", "leaf-on scan: {n:,} points\nwood brown, leaf green"),
                       ("guiding_default_s1_leafoff.ply", "leaf-off scan: {n:,} points (all wood)")):
        cloud = read_points(SYNTH / file)
        scene = with_grid([label_points(cloud.points, cloud.labels, 2.4)])
        panels.append(label(render(scene, (640, 720)), text.format(n=len(cloud.points))))
    save(sheet(panels, 2), "gallery_scans_leafon_leafoff.png")

    cloud = read_points(SYNTH / "guiding_default_s1_missing90.ply")
    dots = [label_points(cloud.points, cloud.labels, 2.4)]
    panels = [label(render(with_grid(dots), (640, 720), view=(45.0, 10.0)),
                    "90-degree sector missing (azimuth 0-90),\nseen from azimuth 45: the open side"),
              label(render(with_grid(dots, grid=False), (640, 720), view="top"), "from above (+X right, +Y up)")]
    save(sheet(panels, 2), "gallery_scan_missing_sector.png")


def lod_closeup(tree_bounds: np.ndarray, lobe_centre: np.ndarray, aspect: float) -> Camera:
    """A camera close to one lobe, looking at it from outside the tree."""
    centre = (tree_bounds[0] + tree_bounds[1]) / 2
    out = lobe_centre - centre
    az = math.degrees(math.atan2(out[1], out[0]))
    box = np.stack([lobe_centre - 0.55, lobe_centre + 0.55])
    return frame(box, aspect, az, 15.0, margin=1.0)


def grown_scene(mesh) -> Scene:
    """Bark and leaf cards of a TreeMesh: textured with the tree's materials (tiling bark, leaves cut
    out of their cards at the texture's alpha) where the parts carry UVs, else flat brown and green."""
    from io import BytesIO

    from arboretum_server.mesh.scene import tree_materials

    materials, items = tree_materials(), []
    for part, rgb in ((mesh.bark, BARK_RGB), (mesh.leaves, FOLIAGE_RGB)):
        if not len(part.faces):
            continue
        mat, look = materials[part.material], {}
        if part.uv is not None and mat.texture_png:
            texture = np.asarray(Image.open(BytesIO(mat.texture_png)).convert("RGBA"))
            normals = None if part.normals is None else f32(part.normals)
            look = {"uv": f32(part.uv), "texture": texture, "normals": normals, "double_sided": mat.double_sided,
                    "alpha_cutoff": mat.alpha_cutoff or 0.0}
            rgb = mat.base_color[:3]
        items.append(Mesh(vertices=f32(part.positions), faces=np.asarray(part.faces, np.int32), color=f32(rgb), **look))
    return with_grid(items)


def section_growth(work: Path) -> None:
    """The demo HBL grown at densities 0.5 / 1 / 2 and meshed at LOD 0 / 1 / 2; a decomposed scan grown."""
    from arboretum_server.grow.demo import demo_hbl
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.lod import LodOptions
    from arboretum_server.mesh.scene import tree_mesh

    hbl = demo_hbl(np.random.default_rng(0))
    trees = {d: grow_tree(hbl, GrowOptions(density=d), np.random.default_rng(7)) for d in (0.5, 1.0, 2.0)}
    meshes = {d: tree_mesh(t) for d, t in trees.items()}
    big = grown_scene(meshes[2.0])
    bounds = big.bounds()
    cam_tall = frame(bounds, 320 / 720, -30.0, 8.0, points=scene_points(big))
    cam_cell = frame(bounds, 320 / 360, -30.0, 8.0, points=scene_points(big))
    cells = [label(render(grown_scene(m), (320, 720), camera=cam_tall),
                   f"density {d:g}\n{len(trees[d].positions):,} nodes\n{len(trees[d].leaves.sizes):,} leaves")
             for d, m in meshes.items()]
    save(sheet(cells, 3), "growth_densities.png")

    tree, top, bottom = trees[1.0], [], []
    lobe = hbl.lobes[int(np.argmax([lb.centre[2] for lb in hbl.lobes]))].centre
    for level in (0, 1, 2):
        scene = grown_scene(tree_mesh(tree, LodOptions(level=level)))
        tris = len(scene.items[0].faces) + (len(scene.items[1].faces) if len(scene.items) > 1 else 0)
        top.append(label(render(scene, (320, 360), camera=cam_cell), f"LOD {level}: {tris:,} triangles", px=16))
        cam = lod_closeup(bounds, np.asarray(lobe, np.float64), 320 / 360)
        bottom.append(label(render(scene, (320, 360), camera=cam), f"LOD {level}, close-up", px=16))
    save(sheet(top + bottom, 3), "growth_lod.png")


def section_modules(work: Path) -> None:
    """Modular trees grown in four crowns: the crown translucent, the modules as instanced meshes."""
    from arboretum_library.assets import asset_path
    from arboretum_server.modules.crown import crown_from_meshes
    from arboretum_server.modules.grow import grow_modular_tree, prepare_modules
    from arboretum_server.modules.moduleset import load_module_set
    from arboretum_server.modules.options import ModularTreeOptions
    from arboretum_server.modules.shapes import box_mesh, sphere_mesh, tetrahedron_mesh, torus_mesh

    crowns = {
        "sphere": [sphere_mesh([0, 0, 6], 3)],
        "torus": [torus_mesh([0, 0, 4.5], 2.5, 1.0)],
        "tetrahedron": [tetrahedron_mesh([0, 0, 4.6], 6.5)],
        "disjoint cubes": [box_mesh([1.0, -0.8, 2.0], [2.6, 0.8, 3.6]), box_mesh([-2.6, -0.8, 2.6], [-1.0, 0.8, 4.2]),
                           box_mesh([-0.8, 1.0, 3.2], [0.8, 2.6, 4.8]), box_mesh([-0.8, -0.8, 4.6], [0.8, 0.8, 6.2])],
    }
    modules = load_module_set(asset_path("modules", "default"))
    options = ModularTreeOptions()
    prepared = prepare_modules(modules, options)
    cells = []
    for name, meshes in crowns.items():
        tree = grow_modular_tree(modules, crown_from_meshes(meshes), options, np.random.default_rng(1), prepared=prepared)
        items = module_items(modules, tree)
        for v, f in meshes:
            items.append(Mesh(vertices=f32(v), faces=np.asarray(f, np.int32), color=f32((0.25, 0.55, 0.85, 0.22))))
        text = f"{name}\n{len(tree.module)} instances, {len(np.unique(tree.module))} types"
        cells.append(label(render(with_grid(items), (320, 720), view="tree"), text, px=16))
    save(sheet(cells, 4), "modules_crowns.png")


def module_items(modules, tree) -> list:
    """One InstancedMesh per module type used (trunks darker than branches)."""
    items = []
    for m in np.unique(tree.module):
        mod = modules.modules[int(m)]
        rgb = (0.30, 0.21, 0.13) if mod.is_trunk else BARK_RGB
        mesh = Mesh(vertices=f32(mod.vertices), faces=np.asarray(mod.faces, np.int32), color=f32(rgb))
        items.append(InstancedMesh(mesh=mesh, matrices=f32(tree.T_world_module[tree.module == m])))
    return items


def section_concepts(work: Path) -> None:
    """One tree's HBL beside its source point cloud (a synthetic leaf-on scan, decomposed)."""
    scan = SYNTH / "guiding_default_s1.ply"
    hbl = decompose(scan, work)  # the HBL and its points are in the decomposition's frame (rescaled)
    pts_scene = with_grid([label_points(hbl.points, hbl.labels, 2.4)])
    items, _ = hbl_items(hbl, HBLStyle(min_radius_fraction=0.002, lobe_alpha=0.3))
    hbl_scene = with_grid(items)
    cam = frame(pts_scene.bounds(), 640 / 720, -60.0, 8.0, points=scene_points(pts_scene))
    mains = sum(1 for b in hbl.branches if int(b.level) == 0)
    panels = [label(render(pts_scene, (640, 720), camera=cam),
                    f"source: synthetic leaf-on scan\n{len(hbl.points):,} points (wood brown, leaf green)"),
              label(render(hbl_scene, (640, 720), camera=cam),
                    f"its HBL: {mains} main branches (red),\n{len(hbl.branches) - mains} secondary (black), "
                    f"{len(hbl.lobes)} lobes")]
    save(sheet(panels, 2), "concept_hbl.png")


def section_decomposition(work: Path) -> None:
    """Each real scan's HBL over its faint cloud; a synthetic scan's HBL beside its truth skeleton."""
    for scan in real_scans():
        hbl, total = decompose(scan, work), len(read_points(scan).points)
        scene = hbl_over_points(hbl)
        z = np.array([lb.centre[2] for lb in hbl.lobes])
        upper = np.concatenate([lb.hull_vertices for lb, zc in zip(hbl.lobes, z) if zc >= np.percentile(z, 40)])
        lo, hi = upper.min(axis=0), upper.max(axis=0)  # the upper 60 % of the lobes
        close = frame(np.stack([lo, hi]), 480 / 720, -60.0, 8.0, margin=1.02)
        mains = sum(1 for b in hbl.branches if int(b.level) == 0)
        panels = [label(render(scene, (480, 720)),
                        f"{scan.stem}\n{len(hbl.points):,} of {total:,} points used"),
                  label(render(scene, (480, 720), camera=close),
                        f"upper crown: {mains} main, {len(hbl.branches) - mains} secondary\nbranches, "
                        f"{len(hbl.lobes)} lobes")]
        save(sheet(panels, 2), f"decomp_{scan.stem}.png")

    scan = SYNTH / "guiding_default_s1.ply"
    hbl, truth = decompose(scan, work), load_truth(SYNTH / "guiding_default_s1_truth.npz")
    truth_scene = with_grid(truth_items(truth, "none", truth_min_radius(truth)))
    hbl_scene = hbl_over_points(hbl)
    panels = [label(render(truth_scene, (640, 720)),
                    f"truth skeleton: {truth.branch_count:,} branches\n(guiding default, seed 1)"),
              label(render(hbl_scene, (640, 720)),
                    f"decomposed from its 12,000-point scan:\n{len(hbl.branches)} branches, {len(hbl.lobes)} lobes")]
    save(sheet(panels, 2), "decomp_synthetic_vs_truth.png")


def section_main_fit(work: Path) -> None:
    """The N_m longest true branches (blue) against the main branches decomposed from a virtual-scanner
    scan (red): a guiding-vector tree, where they part, and a harmonic apple, where they agree."""
    from arboretum_library.model import Level
    from arboretum_library.truth import polyline_length
    from arboretum_server.decompose.evaluate import evaluate
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose as decompose_cloud
    from arboretum_server.decompose.report import grow_truth, virtual_scan

    panels = []
    for model, species, name in (("guiding", "default", "guiding-vector tree (default preset)"),
                                 ("harmonic", "apple", "harmonic apple")):
        truth = grow_truth(model, species, 1)
        pts, labels = virtual_scan(truth, "leaf-off", 1)
        options = DecomposeOptions(species=species)
        d = decompose_cloud(pts, options)

        def to(p, d=d):
            return d.to_output((p - d.root_scan) * d.scale)

        n_main = options.counts()[0]
        m = evaluate(d.hbl, truth, pts[labels == LEAF], to, *options.counts(), scan_points=pts)
        polys = branch_polylines(truth)
        longest = np.argsort([-polyline_length(truth, p) for p in polys])[:n_main]
        r = 0.004 * d.hbl.height
        items = [faint_points(to(pts[::2]), 1.5)]
        items += [Polyline(points=f32(to(truth.positions[polys[i]])), radii=f32(np.full(len(polys[i]), r)),
                           color=f32((0.15, 0.45, 0.95))) for i in longest]
        items += [Polyline(points=f32(b.points), radii=f32(np.full(len(b.points), 0.6 * r)), color=f32((0.85, 0.1, 0.1)))
                  for b in d.hbl.branches if b.level == Level.MAIN]
        panels.append(label(render(with_grid(items), (640, 720), view=(-90.0, 5.0)),
                            f"{name}, leaf-off, virtual scanner\n{n_main} longest true branches (blue), "
                            f"{n_main} main branches (red)\nseen fit {m.main_fit_seen:.3f} of the height"))
    save(sheet(panels, 2), "main_fit_chains.png")


def section_several_trees(work: Path) -> None:
    """Session 7's input checks: a second tree standing higher, named by its trunk column (orange), and
    the weeping elm on sloped ground, whose leaves on the ground no longer read as a second trunk."""
    from arboretum_library.model import Level
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose as decompose_cloud
    from arboretum_server.decompose.preprocess import find_ground
    from arboretum_server.decompose.report import grow_truth, virtual_scan

    def scan(model: str, species: str, seed: int) -> tuple[np.ndarray, float]:
        pts, _ = virtual_scan(grow_truth(model, species, seed), "leaf-on", seed)
        return pts - [*np.median(pts[pts[:, 2] < pts[:, 2].min() + 0.01 * np.ptp(pts[:, 2]), :2], axis=0),
                      pts[:, 2].min()], float(np.ptp(pts[:, 2]))

    first, h = scan("harmonic", "apple", 1)
    second, _ = scan("harmonic", "apple", 2)
    pair = np.r_[first, second + [0.4 * h, 0.0, 0.05 * h]]
    d = decompose_cloud(pair, DecomposeOptions(species="apple"))

    def to(p, d=d):
        return d.to_output((np.asarray(p) - d.root_scan) * d.scale)

    items = hbl_over_points(d.hbl, to(pair[::3])).items
    for c in d.stats["trunk_columns"]:
        foot = np.array(c["foot"])
        line = to(np.stack([foot, foot + [0.0, 0.0, 0.25 * h]]))
        items = (*items, Polyline(points=f32(line), radii=f32([0.012, 0.012]), color=f32((1.0, 0.55, 0.0, 1.0))))
    note = d.stats["trunk_columns"][0] if d.stats["trunk_columns"] else None
    panels = [label(render(with_grid(items), (640, 720), view=(-90.0, 8.0)),
                    "two apples, the second 0.4 of the height away\nand 5 % higher, no ground: one HBL, "
                    + (f"and a note:\ntrunk column {note['distance'] / h:.2f} of the height away (orange)"
                       if note else "no note"))]

    elm, h = scan("guiding", "elm", 1)
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.6, 0.6, (len(elm) // 4, 2)) * h
    ground = np.c_[xy, 0.1 * xy[:, 0] + rng.normal(0, 0.003 * h, len(xy))]
    cloud = np.r_[elm, ground]
    d = decompose_cloud(cloud, DecomposeOptions(species="elm"))
    cut, _ = find_ground(cloud, DecomposeOptions().ground_band)
    r = 0.004 * d.hbl.height
    items = [faint_points(to(cloud[d.source_index[::2]], d), 1.5),
             PointSet(points=f32(to(cloud[cut][::4], d)), colors=f32(np.broadcast_to((0.62, 0.5, 0.3), (len(cloud[cut][::4]), 3))),
                      size_px=2.0)]
    items += [Polyline(points=f32(b.points), radii=f32(np.full(len(b.points), r)), color=f32((0.85, 0.1, 0.1)))
              for b in d.hbl.branches if b.level == Level.MAIN]
    panels.append(label(render(with_grid(items), (640, 720), view=(-90.0, 8.0)),
                        f"guiding elm on a 10 % slope: {d.stats['ground_removed']:,} ground points\nremoved (brown), "
                        f"{len(d.hbl.by_level(Level.MAIN))} main branches (red) from the trunk base;\nits weeping leaves on "
                        "the ground no longer read\nas a second trunk"))
    save(sheet(panels, 2), "several_trees.png")


def section_growth_real(work: Path) -> None:
    """The coffee tree scan decomposed, then grown (twigs and leaves in its lobes)."""
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.scene import tree_mesh

    scan = real_scans()[0]
    hbl = decompose(scan, work)
    tree = grow_tree(hbl, GrowOptions(), np.random.default_rng(7))
    scene = grown_scene(tree_mesh(tree))
    items, _ = hbl_items(hbl, HBLStyle(min_radius_fraction=0.002, lobe_alpha=0.28))
    bounds = scene.bounds()
    panels = [label(render(with_grid(items), (640, 720), bounds=bounds),
                    f"{scan.stem}: decomposed HBL\n{len(hbl.lobes)} lobes"),
              label(render(scene, (640, 720), bounds=bounds),
                    f"grown: {len(tree.positions):,} nodes,\n{len(tree.leaves.sizes):,} leaf cards")]
    save(sheet(panels, 2), "growth_from_scan.png")


SECTIONS = {
    "concepts": [section_concepts],
    "synthetic": [section_synthetic],
    "decomposition": [section_decomposition],
    "main-fit": [section_main_fit],
    "several-trees": [section_several_trees],
    "growth": [section_growth, section_growth_real],
    "modules": [section_modules],
}


def main(argv: list[str]) -> int:
    names = argv or list(SECTIONS)
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        print(f"unknown section(s): {', '.join(unknown)}; choose from {', '.join(SECTIONS)}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="arboretum_pictures_") as tmp:
        for name in names:
            t = time.perf_counter()
            for fn in SECTIONS[name]:
                fn(Path(tmp))
            print(f"{name}: {time.perf_counter() - t:.1f} s")
    print(f"total: {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
