"""Scenes from library records and plain arrays: HBL structures, point clouds, triangle meshes, GLB meshes.

Colours follow the VRTree paper's figures: main branches red, secondary branches black; each lobe is a
translucent hull in its own colour from ``LOBE_PALETTE`` (cycled); source points by label (wood brown,
leaf green). Pick ids are assigned in order and named in ``Scene.names`` ('branch:3', 'lobe:0', ...).

Scene records hold float32 (the GPU's dtype), which resolves only 0.25-0.5 m at UTM coordinates
(4e6 m). Every builder takes an ``origin`` (3,) float64 that is subtracted in float64 before the cast;
``far_origin`` picks one for data far from the world origin, so georeferenced scans draw intact.
"""

from __future__ import annotations

import dataclasses
import io
from dataclasses import dataclass

import numpy as np

from arboretum_library.export.parts import local_origin
from arboretum_library.model import HBL, LEAF, Example, Level

from .scene import InstancedMesh, Mesh, PointSet, Polyline, Scene, grid_for_bounds

BRANCH_COLORS: dict[Level, tuple[float, float, float]] = {
    Level.MAIN: (0.82, 0.08, 0.08),
    Level.SECONDARY: (0.06, 0.06, 0.06),
    Level.TWIG: (0.36, 0.25, 0.15),
}
"""Branch colour per level (VRTree Fig. 3: main red, secondary black)."""

LOBE_PALETTE: tuple[tuple[float, float, float], ...] = (
    (0.12, 0.47, 0.71), (1.00, 0.50, 0.05), (0.17, 0.63, 0.17), (0.58, 0.40, 0.74),
    (0.09, 0.75, 0.81), (0.74, 0.74, 0.13), (0.89, 0.47, 0.76), (0.55, 0.34, 0.29),
    (0.00, 0.50, 0.50), (0.98, 0.75, 0.10), (0.40, 0.65, 1.00), (0.60, 0.80, 0.30),
)
"""Distinct lobe colours (no red or black, which mean branches), used in order and cycled."""

WOOD_COLOR = (0.45, 0.30, 0.16)
LEAF_COLOR = (0.25, 0.62, 0.20)
POINT_COLOR = (0.20, 0.30, 0.45)

far_origin = local_origin
"""(3,) float64 from ``points`` (N, 3): the centre of their bounding box rounded to whole metres when it is
farther than ``parts.FAR`` from the world origin, else zeros; the exporters' ``parts.local_origin``, so a scene
draws about the origin its GLB is written about."""


@dataclass(frozen=True)
class HBLStyle:
    """How an HBL is drawn."""

    min_radius_fraction: float = 0.003
    """Smallest drawn tube radius as a fraction of the structure's bounding-box diagonal."""
    lobe_alpha: float = 0.3
    """Opacity of lobe hulls (0..1)."""
    show_points: bool = False
    """Also draw the source points, coloured by label."""
    point_px: float = 2.0
    """Dot size of source points in pixels."""
    grid: bool = True
    """Draw a ground grid under the structure."""


def hbl_points(hbl: HBL | Example) -> np.ndarray:
    """(N, 3) float64: every point an HBL (or an Example's structure) draws (branches, hulls, points, root)."""
    hbl = hbl.structure if isinstance(hbl, Example) else hbl
    pts = [b.points for b in hbl.branches] + [lb.hull_vertices for lb in hbl.lobes] + [hbl.points]
    return np.concatenate([np.asarray(p, np.float64).reshape(-1, 3) for p in pts] + [hbl.root[None]])


def _diagonal(hbl: HBL) -> float:
    allp = hbl_points(hbl)
    return float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0)))


def hbl_items(hbl: HBL | Example, style: HBLStyle = HBLStyle(), first_id: int = 1,
              origin: np.ndarray | None = None):
    """Items and id names for an HBL (or an Example's structure): branch tubes, lobe hulls, points;
    positions relative to ``origin`` (3,) when given."""
    hbl = hbl.structure if isinstance(hbl, Example) else hbl
    min_r = style.min_radius_fraction * max(_diagonal(hbl), 1e-6)
    items, names, pid = [], {}, first_id
    for i, b in enumerate(hbl.branches):
        items.append(Polyline(points=_local(b.points, origin), radii=_f32(np.maximum(b.radii, min_r)),
                              color=_f32(BRANCH_COLORS[b.level]), pick_id=pid))
        names[pid], pid = f"branch:{i}", pid + 1
    for j, lobe in enumerate(hbl.lobes):
        color = _f32((*LOBE_PALETTE[j % len(LOBE_PALETTE)], style.lobe_alpha))
        items.append(Mesh(vertices=_local(lobe.hull_vertices, origin), faces=lobe.hull_faces, color=color, pick_id=pid))
        names[pid], pid = f"lobe:{j}", pid + 1
    if style.show_points and len(hbl.points):
        colors = _f32(np.where((hbl.labels == LEAF)[:, None], LEAF_COLOR, WOOD_COLOR))
        items.append(PointSet(points=_local(hbl.points, origin), colors=colors, size_px=style.point_px, pick_id=pid))
        names[pid] = "points"
    return items, names


def hbl_scene(hbl: HBL | Example, style: HBLStyle = HBLStyle(), origin: np.ndarray | None = None) -> Scene:
    """A Scene of one HBL structure (with a ground grid when ``style.grid``), relative to ``origin``."""
    items, names = hbl_items(hbl, style, origin=origin)
    return _with_grid(Scene(items=tuple(items), names=names), style.grid)


def points_scene(points: np.ndarray, colors: np.ndarray | None = None, size_px: float = 2.0,
                 grid: bool = True, origin: np.ndarray | None = None) -> Scene:
    """A Scene of a point cloud (N, 3) relative to ``origin`` (3,); ``colors`` (N, 3) in 0..1, or one
    colour for all."""
    pts = _local(np.asarray(points).reshape(-1, 3), origin)
    cols = _f32(np.broadcast_to(POINT_COLOR, pts.shape) if colors is None else colors)
    item = PointSet(points=pts, colors=cols, size_px=size_px, pick_id=1)
    return _with_grid(Scene(items=(item,), names={1: "points"}), grid)


def mesh_scene(vertices: np.ndarray, faces: np.ndarray, color=(0.62, 0.55, 0.45, 1.0), grid: bool = True,
               origin: np.ndarray | None = None) -> Scene:
    """A Scene of one triangle mesh: vertices (V, 3) relative to ``origin`` (3,), faces (F, 3)."""
    item = Mesh(vertices=_local(vertices, origin), faces=np.asarray(faces, np.int32), color=_f32(color), pick_id=1)
    return _with_grid(Scene(items=(item,), names={1: "mesh"}), grid)


def to_rgba8(im) -> np.ndarray:
    """A Pillow image as a new (H, W, 4) uint8 RGBA array. 16-bit grayscale (modes I;16*, and I as
    Pillow opens 16-bit PNGs) is scaled 0..65535 -> 0..255 (Pillow's own convert clips it to white);
    float grayscale (F) is taken as 0..1 when it lies there, else as 0..255."""
    if im.mode.startswith("I;16") or im.mode in ("I", "F"):
        a = np.asarray(im).astype(np.float64)
        if im.mode == "F":
            a = a * 255.0 if np.nanmax(a, initial=0.0) <= 1.0 else a
        else:
            a = a / 257.0
        g = np.clip(np.nan_to_num(a), 0, 255).round().astype(np.uint8)
        return np.dstack([g, g, g, np.full_like(g, 255)])
    return np.asarray(im.convert("RGBA"), np.uint8).copy()


def texture_mean_color(image: bytes) -> np.ndarray:
    """(3,) mean RGB in 0..1 of an embedded PNG/JPEG, weighted by its alpha so cut-out texels do not
    count; white when pillow cannot decode it (the material's factor alone then gives the colour)."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(image)) as im:
            rgba = to_rgba8(im).astype(np.float64) / 255.0
    except (OSError, ValueError):  # pillow's UnidentifiedImageError is an OSError
        return np.ones(3)
    alpha = rgba[..., 3:].reshape(-1, 1)
    return (rgba[..., :3].reshape(-1, 3) * alpha).sum(axis=0) / max(float(alpha.sum()), 1e-9)


def glb_items(meshes, first_id: int = 1, textures: bool = False, source: str = "GLB",
              origin: np.ndarray | None = None):
    """Items and id names for ``GltfMesh`` records (``arboretum_library.export.gltf_read``).

    Flat (``textures`` False): each is drawn in its material's colour (baseColorFactor times the
    texture's mean colour), both faces lit. Textured: with its texture, UVs, normals, alpha mode (MASK:
    cut out below 0.5) and sidedness; identical embedded images are decoded once and shared, so the
    renderer uploads them once (``source`` names the file in errors). A mesh placed K > 1 times becomes
    one ``InstancedMesh`` (one draw call); placed once, or translucent (alphaMode BLEND), it is baked
    into one world-frame ``Mesh``. World positions are taken relative to ``origin`` (3,) when given.
    """
    shift = np.eye(4)
    if origin is not None:
        shift[:3, 3] = -np.asarray(origin, np.float64)
    items, names, images = [], {}, {}
    for g in (g for g in meshes if len(g.faces)):
        pid = first_id + len(items)
        rgb = g.base_color[:3] * (texture_mean_color(g.texture) if g.texture is not None else 1.0)
        color = _f32((*np.clip(rgb, 0.0, 1.0), g.base_color[3] if g.alpha_mode == "BLEND" else 1.0))
        if len(g.instances) > 1 and color[3] >= 1.0:
            item = InstancedMesh(Mesh(_f32(g.positions), g.faces, color, pid), _f32(shift @ g.instances))
        else:
            verts = np.concatenate([g.positions @ T[:3, :3].T + T[:3, 3] for T in shift @ g.instances])
            faces = (g.faces[None] + len(g.positions) * np.arange(len(g.instances))[:, None, None]).reshape(-1, 3)
            item = Mesh(_f32(verts), faces.astype(np.int32), color, pid)
        items.append(_textured(item, g, images, source) if textures else item)
        names[pid] = g.name
    return items, names


def glb_scene(meshes, grid: bool = True, textures: bool = False, source: str = "GLB",
              origin: np.ndarray | None = None) -> Scene:
    """A Scene of the meshes read from a GLB (``gltf_read.read_glb``), with a ground grid when ``grid``
    (textured as ``glb_items``, relative to ``origin``)."""
    items, names = glb_items(meshes, textures=textures, source=source, origin=origin)
    return _with_grid(Scene(items=tuple(items), names=names), grid)


def _textured(item, g, images: dict[bytes, np.ndarray], source: str):
    """``item`` (a Mesh or InstancedMesh made from GltfMesh ``g``) textured like ``g``'s material."""
    if g.texture is None or g.uvs is None:
        return item
    if g.texture not in images:
        images[g.texture] = decode_texture(g.texture, source)
    instanced = isinstance(item, InstancedMesh)
    mesh = item.mesh if instanced else item
    k = 1 if instanced else len(g.instances)  # a baked mesh holds its K placements, in order
    normals = None if g.normals is None else _placed_normals(g.normals, None if instanced else g.instances)
    rgb = np.clip(g.base_color[:3], 0.0, 1.0)
    textured = dataclasses.replace(
        mesh, color=np.array([*rgb, mesh.color[3]], np.float32), uv=np.tile(g.uvs, (k, 1)),
        texture=images[g.texture], normals=normals, double_sided=bool(g.double_sided),
        alpha_cutoff=0.5 if g.alpha_mode == "MASK" else 0.0)
    return dataclasses.replace(item, mesh=textured) if instanced else textured


def _placed_normals(normals: np.ndarray, instances: np.ndarray | None) -> np.ndarray:
    """Normals (V, 3) as they are (``instances`` None), or under each of (K, 4, 4) ``instances``
    (inverse-transpose, renormalised) stacked to (K * V, 3), matching a baked mesh's vertices."""
    if instances is None:
        return np.asarray(normals, np.float32)
    out = np.concatenate([normals @ np.linalg.inv(T[:3, :3]) for T in instances])
    return (out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)).astype(np.float32)


def decode_texture(data: bytes, source: str = "GLB") -> np.ndarray:
    """An embedded PNG/JPEG image as a read-only (H, W, 4) uint8 RGBA array; InputError naming ``source``
    if unreadable."""
    from PIL import Image, UnidentifiedImageError

    from arboretum_library.errors import InputError

    try:
        with Image.open(io.BytesIO(data)) as im:
            rgba = to_rgba8(im)
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise InputError(f"{source}: an embedded texture is not a readable PNG or JPEG image ({exc})") from None
    rgba.flags.writeable = False
    return rgba


def _f32(values) -> np.ndarray:
    """float32 array of ``values`` (the GPU-side dtype of scene records)."""
    return np.asarray(values, dtype=np.float32)


def _local(values, origin: np.ndarray | None) -> np.ndarray:
    """float32 of float64 ``values`` (..., 3) minus ``origin`` (3,) (subtracted before the cast)."""
    values = np.asarray(values, np.float64)
    return _f32(values if origin is None else values - np.asarray(origin, np.float64))


def _with_grid(scene: Scene, grid: bool) -> Scene:
    return dataclasses.replace(scene, grid=grid_for_bounds(scene.bounds()) if grid and scene.items else None)


def _renumber(item, offset: int):
    if isinstance(item, InstancedMesh):
        return dataclasses.replace(item, mesh=_renumber(item.mesh, offset))
    return dataclasses.replace(item, pick_id=item.pick_id + offset if item.pick_id else 0)


def combine(*scenes: Scene, grid: bool = True) -> Scene:
    """One Scene holding the items of ``scenes``, pick ids renumbered to stay unique."""
    items, names, offset = [], {}, 0
    for sc in scenes:
        items += [_renumber(it, offset) for it in sc.items]
        names.update({k + offset: v for k, v in sc.names.items()})
        offset += max([0, *sc.names, *(it.pick_id for it in sc.items)])
    return _with_grid(Scene(items=tuple(items), names=names), grid)
