"""Shared helpers of the VRTree section 4 experiment scripts (examples/0*.py).

Each script builds example libraries in memory (scan -> ``decompose`` -> ``make_examples``), places
examples with the assembly operations of the server (``arboretum_server.assembly.ops``), joins them
with ``assembly_to_hbl`` and draws the results with the client's headless renderer (EGL). Every figure a
script measures is printed as one JSON document on stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # scikit-learn threads must not spin (FACTS.md)

from arboretum_library.assets import asset_path  # noqa: E402
from arboretum_library.geometry import axis_angle_matrix, make_transform  # noqa: E402
from arboretum_library.model import HBL, Example  # noqa: E402

BARK_RGB = (0.42, 0.30, 0.20, 1.0)
FOLIAGE_RGB = (0.30, 0.58, 0.22, 1.0)
BLACK = (0.0, 0.0, 0.0, 1.0)


def parse_args(doc: str) -> argparse.Namespace:
    """``--out DIR`` (pictures) and ``--seed N`` (every random choice)."""
    p = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    p.add_argument("--out", default="out", help="folder for the pictures (created)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    args = p.parse_args()
    args.out = Path(args.out)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def emit(summary: dict) -> None:
    """Print the measured figures as one JSON document."""
    json.dump(summary, sys.stdout, indent=2, sort_keys=True)
    sys.stdout.write("\n")


# ---------------------------------------------------------------- libraries


def synth_scan(species: str, seed: int, points: int = 8000) -> tuple[np.ndarray, np.ndarray]:
    """A harmonic-species tree (``grow_species``) scanned by the virtual scanner: (points, labels)."""
    from arboretum_server.synth.harmonic import grow_species
    from arboretum_server.synth.scanner import ScanOptions, scan

    truth = grow_species(species, seed=seed)
    s = scan(truth, ScanOptions(points=points), np.random.default_rng(seed))
    return s.points, s.labels


def real_scan(name: str) -> tuple[np.ndarray, None]:
    """The bundled real scan ``assets/scans/NAME/NAME.xyz``: (points, None)."""
    from arboretum_library.pointio import read_points

    return read_points(asset_path("scans", name, f"{name}.xyz")).points, None


def synth_asset(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A bundled synthetic scan ``assets/synth/NAME``: (points, labels)."""
    from arboretum_library.pointio import read_points

    cloud = read_points(asset_path("synth", name))
    return cloud.points, cloud.labels


def library(points: np.ndarray, labels: np.ndarray | None, species: str, prefix: str, seed: int,
            height: float | None = 0.8, points_used: int = 8000, n_lobes: int | None = None):
    """Decompose one scan into examples: (Decomposition, [Example]) with ids ``prefix-000``, ..."""
    from arboretum_server.decompose.examples import counter_ids, make_examples, provenance
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    o = DecomposeOptions(species=species, height=height, points=points_used, seed=seed, n_lobes=n_lobes)
    dec = decompose(points, o, labels=labels)
    return dec, make_examples(dec.hbl, provenance(f"{prefix}.scan", o, sha256=""), counter_ids(prefix))


def source(*groups: list[Example]):
    """An ``ExampleSource`` (id -> Example) over lists of examples."""
    by_id = {e.id: e for g in groups for e in g}
    return by_id.__getitem__


# ---------------------------------------------------------------- transforms


def rot_z(degrees: float, about: np.ndarray = np.zeros(3), at: np.ndarray = np.zeros(3)) -> np.ndarray:
    """4x4: turn by ``degrees`` about the vertical through ``about``, then move by ``at``."""
    R = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), math.radians(degrees))
    about = np.asarray(about, np.float64)
    return make_transform(R, about - R @ about + np.asarray(at, np.float64))


def azimuth(example: Example) -> float:
    """Degrees: the horizontal direction from the main branch's base to its tip."""
    p = example.structure.branches[0].points
    d = p[-1] - p[0]
    return math.degrees(math.atan2(d[1], d[0]))


def branch_key(points: np.ndarray, radii: np.ndarray) -> bytes:
    """Bytes identifying a branch exactly (bit-for-bit) by its vertices and radii."""
    return np.ascontiguousarray(points, np.float64).tobytes() + np.ascontiguousarray(radii, np.float64).tobytes()


# ---------------------------------------------------------------- pictures


def grown_items(hbl: HBL, seed: int, density: float = 0.6, offset=(0.0, 0.0, 0.0)) -> tuple[list, dict]:
    """Bark and leaf meshes of ``hbl`` grown by space colonisation (moved by ``offset``), and counts."""
    from arboretum_client.scene import Mesh
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree
    from arboretum_server.mesh.scene import tree_mesh

    tree = grow_tree(hbl, GrowOptions(density=density), np.random.default_rng(seed))
    mesh = tree_mesh(tree)
    off = np.asarray(offset, np.float32)
    items = [Mesh(vertices=np.asarray(mesh.bark.positions, np.float32) + off,
                  faces=np.asarray(mesh.bark.faces, np.int32), color=np.asarray(BARK_RGB, np.float32))]
    if len(mesh.leaves.faces):
        items.append(Mesh(vertices=np.asarray(mesh.leaves.positions, np.float32) + off,
                          faces=np.asarray(mesh.leaves.faces, np.int32), color=np.asarray(FOLIAGE_RGB, np.float32)))
    return items, {"nodes": int(len(tree.positions)), "leaves": int(len(tree.leaves.sizes))}


def structure_items(hbl: HBL, offset=(0.0, 0.0, 0.0), lobe_alpha: float = 0.3, color=None) -> list:
    """Branch tubes and lobe hulls of ``hbl`` (the client's HBL style), moved by ``offset``;
    ``color`` (RGBA) paints every item in one colour (for silhouettes)."""
    from dataclasses import replace

    from arboretum_client.scene_build import HBLStyle, hbl_items

    items, _ = hbl_items(hbl, HBLStyle(lobe_alpha=lobe_alpha))
    off = np.asarray(offset, np.float32)
    out = []
    for it in items:
        moved = replace(it, points=it.points + off) if hasattr(it, "points") else replace(it, vertices=it.vertices + off)
        out.append(moved if color is None else replace(moved, color=np.asarray(color, np.float32)))
    return out


def camera_for(items: list, size: tuple[int, int], view: str = "front", margin: float = 1.08):
    """The client's ``fit_camera`` on the items' bounding box."""
    from arboretum_client.camera import fit_camera
    from arboretum_client.scene import Scene

    return fit_camera(Scene(items=tuple(items)).bounds(), view, size[0] / size[1], margin=margin)


def render(items: list, size: tuple[int, int], camera, grid: bool = True) -> np.ndarray:
    """(H, W, 3) uint8 headless render of ``items`` with ``camera``."""
    from dataclasses import replace

    from arboretum_client.headless import render_image
    from arboretum_client.scene import Scene, grid_for_bounds

    scene = Scene(items=tuple(items))
    if grid:
        scene = replace(scene, grid=grid_for_bounds(scene.bounds()))
    return render_image(scene, size, camera)[:, :, :3]


def silhouette(items: list, size: tuple[int, int], camera) -> np.ndarray:
    """(H, W) bool: the pixels covered by ``items`` drawn opaque black (no grid) over the light background."""
    from dataclasses import replace

    black = [replace(it, color=np.asarray(BLACK, np.float32)) if hasattr(it, "color") else it for it in items]
    img = render(black, size, camera, grid=False)
    return img.astype(np.int32).sum(axis=2) < 3 * 100


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def labelled(img: np.ndarray, text: str) -> np.ndarray:
    """``img`` (H, W, 3) uint8 with ``text`` (several lines allowed) in its top-left corner."""
    from PIL import Image, ImageDraw

    im = Image.fromarray(np.ascontiguousarray(img))
    ImageDraw.Draw(im).multiline_text((8, 6), text, fill=(25, 25, 30))
    return np.asarray(im)


def save(img: np.ndarray, path: Path) -> Path:
    """Write an RGB uint8 image (H, W, 3) as PNG."""
    from PIL import Image

    Image.fromarray(np.ascontiguousarray(img)).save(path, optimize=True)
    return path


def side_by_side(images: list[np.ndarray]) -> np.ndarray:
    """Images of the same height next to each other, separated by a 2-pixel grey line."""
    h = images[0].shape[0]
    gap = np.full((h, 2, 3), 200, np.uint8)
    parts = []
    for im in images:
        parts += [im, gap]
    return np.concatenate(parts[:-1], axis=1)


def about_base(example: Example, degrees: float, scale: float = 1.0, root=np.zeros(3)) -> np.ndarray:
    """4x4 rigid T for a placement of ``example`` (with uniform ``scale``) that turns it by ``degrees``
    about the vertical through ``root`` and scales it about its main branch's base (which stays put
    on that turned circle)."""
    base = example.structure.branches[0].points[0]
    turn = rot_z(degrees, root)
    R = turn[:3, :3]
    moved = R @ base + turn[:3, 3]
    return make_transform(R, moved - scale * (R @ base))


def hbl_figures(hbl: HBL) -> dict:
    """Counts and size of an HBL: branches, lobes, height, width (metres) and height / width."""
    pts = np.concatenate([b.points for b in hbl.branches] + [lb.hull_vertices for lb in hbl.lobes])
    h = float(pts[:, 2].max() - hbl.root[2])
    w = float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1])))
    return {"branches": len(hbl.branches), "lobes": len(hbl.lobes), "height": round(h, 4),
            "width": round(w, 4), "height_width": round(h / w, 3) if w > 0 else 0.0}


def attach(a, get, name: str):
    """``a`` with placement ``name`` joined (as b) to the placed main branch it touches that is most similar
    (the recombination rule and Algorithm 1, applied to ``name`` only: no other placement changes)."""
    from dataclasses import replace

    from arboretum_server.assembly.recombine import RecombineOptions, candidate
    from arboretum_server.assembly.world import main_world

    mains = {p.instance: main_world(p, get(p.example_id)) for p in a.placements}
    found = [c for n in mains if n != name and (c := candidate(n, mains[n], name, mains[name], RecombineOptions()))]
    return replace(a, merges=a.merges + (min(found, key=lambda c: c[0])[1],)) if found else a
