"""``arboretum render INPUT... --out img.png``: a picture of point clouds, HBL records and meshes.

INPUT may be a point cloud (.xyz/.txt/.pts/.csv text with x y z first, .las/.laz/.pcd/.npy, a
face-less .ply; read by ``arboretum_library.pointio``),
an HBL or Example record (.npz written by ``arboretum_library.codec.save_record``), a triangle mesh
(.ply with faces, .obj), or a binary glTF (.glb: grown trees, instanced module trees; read by
``arboretum_library.export.gltf_read``; drawn with its textures, alpha modes and double-sidedness
unless ``--no-textures``). Several inputs are drawn together. Rendering is headless (EGL).

``--up`` (auto, y, z; ``arboretum_library.export.mesh_up``) is the up axis of point cloud, .obj and .ply
inputs; HBL records are Z up and .glb Y up. With ``auto`` an .obj is read by Arboretum's header, else
as Y up (as Blender and Maya write it), and a .ply mesh as Z up, unless its vertices surely stand along
the other axis; point clouds as ``arboretum scan --up auto`` reads them. Inputs far from the world origin (georeferenced scans
in UTM coordinates) are drawn relative to the centre of all inputs, taken in float64 before the GPU's
float32 (``scene_build.far_origin``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from arboretum_library.checks import check_input_file
from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output
from arboretum_library.pointio import UP_CHOICES

VIEW_CHOICES = ("front", "side", "top", "iso")


def register(subparsers) -> None:
    p = subparsers.add_parser("render", help="render point clouds, HBL records, meshes and GLBs to a PNG (headless)")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="point cloud, HBL/Example .npz, mesh .ply/.obj, or .glb")
    p.add_argument("--out", required=True, help="PNG file to write (.png, in an existing folder)")
    p.add_argument("--view", choices=VIEW_CHOICES, default="iso", help="camera direction (default iso)")
    p.add_argument("--size", default="1280x720", help="image size WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--up", choices=UP_CHOICES, default="auto",
                   help="up axis of point cloud, .obj and .ply inputs: auto (default), y or z (records are "
                        "Z up, .glb Y up)")
    p.add_argument("--points", action="store_true", help="also draw an HBL's source points by label")
    p.add_argument("--no-grid", action="store_true", help="leave out the ground grid")
    p.add_argument("--no-textures", action="store_true",
                   help="draw GLB materials in one flat colour each (the texture's mean) instead of textured")
    add_json_flag(p)
    p.set_defaults(func=run)


def parse_size(text: str) -> tuple[int, int]:
    """'1280x720' -> (1280, 720); InputError for anything else."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size: {text!r} is not WIDTHxHEIGHT, e.g. 1280x720") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise InputError(f"--size: {w}x{h} is outside 16..8192 pixels per side")
    return w, h


def run(args: argparse.Namespace) -> int:
    from .headless import OffscreenRenderer, save_png
    from .scene_build import HBLStyle, combine, far_origin

    size = parse_size(args.size)
    for path in args.inputs:
        check_input_file(path, "INPUT")
    check_output(args.out, "--out", inputs=args.inputs, suffixes=(".png",))
    t0 = time.perf_counter()
    style = HBLStyle(show_points=args.points, grid=False)
    textures = not getattr(args, "no_textures", False)
    loaded = [read_input(Path(p), style, textures, getattr(args, "up", "auto")) for p in args.inputs]
    origin = far_origin(np.concatenate([corners for corners, _ in loaded]))
    scene = combine(*(build(origin) for _, build in loaded), grid=not args.no_grid)
    with OffscreenRenderer(size) as r:
        image = r.render(scene, view=args.view)
        stats = r.renderer.stats
    out = save_png(image, args.out)
    data = {"out": str(out), "size": list(size), "view": args.view, "inputs": args.inputs,
            "draw_calls": stats.draw_calls, "triangles": stats.triangles, "points": stats.points,
            "seconds": round(time.perf_counter() - t0, 3)}
    emit(args, data, f"wrote {out} ({size[0]}x{size[1]}, {args.view} view, {stats.triangles} triangles, "
                     f"{stats.points} points)")
    return 0


def load_scene(path: Path, style, textures: bool = True):
    """A Scene for one input file, chosen by its extension (and content for .ply); a GLB's meshes are
    textured unless ``textures`` is False. Far from the world origin, it is centred (``far_origin``)."""
    from .scene_build import far_origin

    corners, build = read_input(path, style, textures)
    return build(far_origin(corners))


def read_input(path: Path, style, textures: bool = True, up: str = "auto"):
    """(corners, build) for one input file: its (2, 3) float64 world bounding box, and a function taking
    an origin (3,) to the input's Scene relative to it (see ``load_scene``). ``up``: the up axis of a
    point cloud, .obj or .ply (``--up``)."""
    from arboretum_library.export.mesh_up import mesh_up_axis

    from .scene_build import glb_scene, hbl_points, hbl_scene, mesh_scene, points_scene

    check_input_file(str(path), "INPUT")
    ext = path.suffix.lower()
    if ext == ".glb":
        from arboretum_library.export.gltf_read import read_glb

        mesh_up_axis(path, np.zeros((0, 3)), up)  # --up z is refused: glTF is Y up
        meshes = read_glb(path)
        return _glb_corners(meshes), lambda o: glb_scene(meshes, False, textures, str(path), origin=o)
    if ext == ".gltf":
        raise InputError(f"{path}: only binary glTF (.glb) is read; save it as .glb")
    if ext == ".npz":
        hbl = load_hbl(path)
        return _corners(hbl_points(hbl)), lambda o: hbl_scene(hbl, style, origin=o)
    if ext in (".obj", ".ply"):
        verts, faces = _stored_obj(path) if ext == ".obj" else read_ply(path)
        if len(faces):
            verts = upright(path, verts, up)
            return _corners(verts), lambda o: mesh_scene(verts, faces, grid=False, origin=o)
    points, colors = read_point_cloud(path, up)
    return _corners(points), lambda o: points_scene(points, colors, grid=False, origin=o)


def _corners(points: np.ndarray) -> np.ndarray:
    """(2, 3) float64 bounding-box corners of ``points`` (N, 3); (0, 3) when there are none."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    return np.stack([p.min(axis=0), p.max(axis=0)]) if len(p) else p


def _glb_corners(meshes) -> np.ndarray:
    """(2, 3) world bounding-box corners of GLB meshes: each mesh's box corners under each placement."""
    boxes = []
    for g in (g for g in meshes if len(g.positions)):
        lo, hi = g.positions.min(axis=0), g.positions.max(axis=0)
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        boxes.append(np.einsum("kij,nj->kni", g.instances[:, :3, :3], box).reshape(-1, 3)
                     + np.repeat(g.instances[:, :3, 3], 8, axis=0))
    return _corners(np.concatenate(boxes)) if boxes else np.zeros((0, 3))


def load_hbl(path: Path):
    """An HBL or Example from a record .npz (``codec.save_record``); ``InputError`` for anything else."""
    from arboretum_library import codec
    from arboretum_library.model import HBL, Example

    types = {"HBL": HBL, "Example": Example}
    kind = codec.record_kind(path)
    if kind not in types:
        raise InputError(f"{path}: holds a {kind!r} record; render reads HBL or Example records")
    return codec.load_record(path, types[kind])


def read_point_cloud(path: Path, up: str = "auto") -> tuple[np.ndarray, np.ndarray | None]:
    """Points (N, 3) Z up (``up``: the file's, as ``pointio.ReadOptions.up``) and colours (N, 3) or None
    (from the file's colours, else its wood/leaf labels)."""
    from arboretum_library.pointio import ReadOptions, read_points

    cloud = read_points(path, ReadOptions(up=up))
    colors = cloud.colors
    if colors is None and cloud.labels is not None:
        from .scene_build import LEAF_COLOR, WOOD_COLOR

        colors = np.where((cloud.labels == 1)[:, None], LEAF_COLOR, WOOD_COLOR)
    return np.asarray(cloud.points, np.float64), colors


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) as stored and triangles (F, 3) of a .ply (polygons fan-triangulated; F = 0 for
    clouds)."""
    from plyfile import PlyData

    try:
        ply = PlyData.read(str(path))
        v = ply["vertex"]
        verts = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    except Exception as exc:  # plyfile raises several types for malformed files
        raise InputError(f"{path}: not a readable PLY with x, y, z vertices ({exc})") from None
    names = [e.name for e in ply.elements]
    if "face" not in names or len(ply["face"].data) == 0:
        return verts, np.zeros((0, 3), np.int64)
    prop = ply["face"].data.dtype.names[0]
    return verts, _triangulate([np.asarray(f, np.int64) for f in ply["face"].data[prop]], len(verts), path)


def read_obj(path: Path, up: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 Z up and triangles (F, 3) of a Wavefront .obj (v and f lines only); its up
    axis by ``up`` (``upright``)."""
    verts, faces = _stored_obj(path)
    return upright(path, verts, up), faces


def upright(path: Path, verts: np.ndarray, up: str = "auto") -> np.ndarray:
    """``verts`` (V, 3) of the .obj or .ply mesh ``path``, as stored, turned Z up when its up axis
    (``export.mesh_up.mesh_up_axis``: ``up``, else Arboretum's header, else the format's usual axis unless
    the vertices surely stand along the other) is Y."""
    from arboretum_library.export.mesh_up import mesh_up_axis
    from arboretum_library.geometry import yup_to_zup

    return yup_to_zup(verts) if mesh_up_axis(path, verts, up) == "y" else verts


def _stored_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 as stored and triangles (F, 3) of a Wavefront .obj (v and f lines only)."""
    verts, polys = [], []
    for line in path.read_text(errors="replace").splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            polys.append(np.array([int(p.split("/")[0]) for p in parts[1:]], np.int64))
    if not verts or not polys:
        raise InputError(f"{path}: an OBJ needs 'v' and 'f' lines, found {len(verts)} and {len(polys)}")
    nv = len(verts)
    polys = [np.where(p < 0, nv + p, p - 1) for p in polys]  # 1-based, negatives count from the end
    return np.asarray(verts, np.float64), _triangulate(polys, nv, path)


def _triangulate(polys: list[np.ndarray], n_verts: int, path: Path) -> np.ndarray:
    tris = [np.stack([np.full(len(p) - 2, p[0]), p[1:-1], p[2:]], axis=1) for p in polys if len(p) >= 3]
    faces = np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= n_verts):
        raise InputError(f"{path}: a face refers to a vertex that does not exist")
    return faces
