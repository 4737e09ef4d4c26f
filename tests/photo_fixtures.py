"""Photographs of a synthetic tree of known shape, rendered headless, for the photos tests and bench.

The tree is a ``TreeTruth`` skeleton drawn as one cylinder per edge (radii thickened and never below
``min_radius`` so thin twigs stay visible) with its leaf cards (enlarged by ``leaf_scale``), standing on
a square of ground. Both carry a procedural texture computed in
the fragment shader from the WORLD position (value noise at three frequencies), so a surface point looks
the same from every view and SIFT finds features that match across views. Views stand on a ring around
the trunk, alternating between two heights, all looking at the crown's centre.

Rendering uses our own tiny moderngl program on the client's headless context (the client renderer
draws one colour per mesh, not a texture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from arboretum_library.truth import TreeTruth

VERT = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec3 in_normal;
in float in_kind;
out vec3 v_world;
out vec3 v_normal;
out float v_kind;
void main() {
    v_world = in_pos; v_normal = in_normal; v_kind = in_kind;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""

FRAG = """
#version 330
uniform vec3 eye;
in vec3 v_world;
in vec3 v_normal;
in float v_kind;
out vec4 f_color;
float hash(vec3 p) {
    p = fract(p * 0.3183099 + vec3(0.71, 0.113, 0.419));
    p *= 17.0;
    return fract(p.x * p.y * p.z * (p.x + p.y + p.z));
}
float vnoise(vec3 x) {
    vec3 i = floor(x); vec3 f = fract(x); f = f * f * (3.0 - 2.0 * f);
    return mix(mix(mix(hash(i), hash(i + vec3(1,0,0)), f.x), mix(hash(i + vec3(0,1,0)), hash(i + vec3(1,1,0)), f.x), f.y),
               mix(mix(hash(i + vec3(0,0,1)), hash(i + vec3(1,0,1)), f.x), mix(hash(i + vec3(0,1,1)), hash(i + vec3(1,1,1)), f.x), f.y), f.z);
}
void main() {
    float f = (v_kind > 0.5 && v_kind < 1.5) ? 1.0 : 3.0;
    float n = 0.45 * vnoise(v_world * 3.0 * f) + 0.35 * vnoise(v_world * 7.0 * f) + 0.2 * vnoise(v_world * 16.0 * f);
    vec3 base = v_kind > 1.5 ? vec3(0.30, 0.62, 0.22) : (v_kind > 0.5 ? vec3(0.45, 0.55, 0.35) : vec3(0.55, 0.38, 0.22));
    vec3 nrm = normalize(v_normal);
    float light = 0.55 + 0.45 * abs(dot(nrm, normalize(eye - v_world)));
    f_color = vec4(base * (0.25 + 1.5 * n) * light, 1.0);
}
"""


@dataclass(frozen=True)
class PhotoSet:
    """Rendered views of a known tree."""

    folder: Path
    """Where the PNG images are (view_000.png, ...)."""
    names: list[str]
    """Image file names, in view order."""
    centres: np.ndarray
    """(V, 3) float64, metres, world: true camera centres."""
    focal_px: float
    """True focal length in pixels (square pixels, principal point at the image centre)."""
    surface: np.ndarray
    """(M, 3) float64, metres, world: samples on the rendered tree's surface, wood and leaves (no ground)."""
    truth: TreeTruth
    """The skeleton as rendered (radii times ``thicken``, at least ``min_radius``)."""
    ground_z: float
    """Height of the rendered ground square (the tree's root height)."""


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ref = np.where(np.abs(axis[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    n1 = np.cross(axis, ref)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    return n1, np.cross(axis, n1)


def cylinders(truth: TreeTruth, sides: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One open cylinder per skeleton edge: vertices (V, 3), normals (V, 3), faces (F, 3)."""
    child = np.arange(1, truth.node_count)
    a, b = truth.positions[truth.parent[child]], truth.positions[child]
    ra, rb = truth.radii[truth.parent[child]], truth.radii[child]
    axis = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1, keepdims=True), 1e-12)
    n1, n2 = _frame(axis)
    th = 2 * np.pi * np.arange(sides) / sides
    radial = np.cos(th)[None, :, None] * n1[:, None] + np.sin(th)[None, :, None] * n2[:, None]
    ring_a = a[:, None] + ra[:, None, None] * radial
    ring_b = b[:, None] + rb[:, None, None] * radial
    verts = np.concatenate([ring_a, ring_b], axis=1).reshape(-1, 3)
    normals = np.concatenate([radial, radial], axis=1).reshape(-1, 3)
    k = np.arange(sides)
    k1 = (k + 1) % sides
    quad = np.stack([np.stack([k, k1, sides + k1], 1), np.stack([k, sides + k1, sides + k], 1)], 1).reshape(-1, 3)
    faces = (np.arange(len(child))[:, None, None] * 2 * sides + quad[None]).reshape(-1, 3)
    return verts, normals, faces


def leaf_cards(truth: TreeTruth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two triangles per leaf card (``truth.leaf_card_corners``): vertices, normals, faces."""
    from arboretum_library.truth import leaf_card_corners

    corners = leaf_card_corners(truth)
    if len(corners) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    faces = (4 * np.arange(len(corners))[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])[None]).reshape(-1, 3)
    return corners.reshape(-1, 3), np.repeat(n, 4, axis=0), faces


def ground_square(centre: np.ndarray, half: float, z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square of ground (4 vertices, 2 faces) at height ``z``."""
    c = np.asarray(centre, np.float64)
    v = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64) * half + c[:2]
    verts = np.c_[v, np.full(4, z)]
    return verts, np.tile([0.0, 0.0, 1.0], (4, 1)), np.array([[0, 1, 2], [0, 2, 3]])


def ring_cameras(target: np.ndarray, radius: float, heights: tuple[float, float], views: int) -> np.ndarray:
    """(V, 3) camera centres on a ring about ``target``'s vertical axis, alternating two heights."""
    az = 2 * np.pi * np.arange(views) / views
    z = np.where(np.arange(views) % 2 == 0, heights[0], heights[1])
    return np.c_[target[0] + radius * np.cos(az), target[1] + radius * np.sin(az), z]


def render_photos(truth: TreeTruth, folder: Path, views: int = 24, size: tuple[int, int] = (1024, 768),
                  fov_y: float = 50.0, min_radius: float = 0.04, thicken: float = 2.0,
                  leaf_scale: float = 3.0, samples: int = 20_000, seed: int = 0) -> PhotoSet:
    """Render ``views`` PNG photographs of ``truth`` into ``folder``; see ``PhotoSet``."""
    from arboretum_client.camera import look_at, perspective
    from arboretum_client.context import create_headless_context

    shown = replace(truth, radii=np.maximum(thicken * truth.radii, min_radius),
                    leaf_sizes=leaf_scale * truth.leaf_sizes)
    lo, hi = shown.positions.min(0), shown.positions.max(0)
    target = (lo + hi) / 2
    extent = float(np.linalg.norm(hi - lo))
    tv, tn, tf = cylinders(shown)
    lv, ln, lf = leaf_cards(shown)
    gv, gn, gf = ground_square(target, 0.4 * extent, float(shown.positions[0, 2]))
    pos = np.concatenate([tv, lv, gv]).astype("f4")
    nrm = np.concatenate([tn, ln, gn]).astype("f4")
    kind = np.concatenate([np.zeros(len(tv)), np.full(len(lv), 2.0), np.ones(len(gv))]).astype("f4")
    faces = np.concatenate([tf, lf + len(tv), gf + len(tv) + len(lv)]).astype("i4")
    w, h = size
    tall = hi[2] - lo[2]
    centres = ring_cameras(target, 0.65 * extent, (lo[2] + 0.6 * tall, lo[2] + 1.1 * tall), views)
    folder.mkdir(parents=True, exist_ok=True)
    names = [f"view_{i:03d}.png" for i in range(views)]
    ctx = create_headless_context()
    try:
        prog = ctx.program(vertex_shader=VERT, fragment_shader=FRAG)
        vbo = ctx.buffer(np.concatenate([pos, nrm, kind[:, None]], axis=1).tobytes())
        ibo = ctx.buffer(faces.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f 1f", "in_pos", "in_normal", "in_kind")], ibo)
        fbo = ctx.simple_framebuffer((2 * w, 2 * h), samples=0)  # drawn at 2x, averaged: no aliasing
        P = perspective(fov_y, w / h, 0.05, 4 * extent)
        for name, eye in zip(names, centres):
            _draw(ctx, fbo, vao, prog, P @ look_at(eye, target, [0.0, 0.0, 1.0]), eye)
            _save(fbo, (w, h), folder / name)
        assert ctx.error == "GL_NO_ERROR", ctx.error
    finally:
        ctx.release()
    focal = (h / 2) / math.tan(math.radians(fov_y) / 2)
    surface = tree_surface(shown, samples, np.random.default_rng(seed))
    return PhotoSet(folder, names, centres, focal, surface, shown, float(shown.positions[0, 2]))


def tree_surface(truth: TreeTruth, samples: int, rng: np.random.Generator) -> np.ndarray:
    """(samples, 3) points uniform by area over the wood cones and the leaf ellipses of ``truth``."""
    from arboretum_library.truth import LEAF_WIDTH_RATIO
    from arboretum_server.synth.scanner import sample_leaves, sample_wood

    child = np.arange(1, truth.node_count)
    length = np.linalg.norm(truth.positions[child] - truth.positions[truth.parent[child]], axis=1)
    wood = float((np.pi * (truth.radii[child] + truth.radii[truth.parent[child]]) * length).sum())
    leaf = float((np.pi / 4 * truth.leaf_sizes**2 * LEAF_WIDTH_RATIO).sum())
    m_leaf = int(round(samples * leaf / (wood + leaf)))
    parts = [sample_wood(truth, samples - m_leaf, rng).points]
    if m_leaf:
        parts.append(sample_leaves(truth, m_leaf, rng).points)
    return np.concatenate(parts)


def _draw(ctx, fbo, vao, prog, mvp: np.ndarray, eye: np.ndarray) -> None:
    import moderngl

    fbo.use()
    fbo.clear(0.78, 0.84, 0.92, 1.0)
    ctx.enable(moderngl.DEPTH_TEST)
    prog["mvp"].write(mvp.T.astype("f4").tobytes())
    prog["eye"].value = tuple(float(x) for x in eye)
    vao.render()


def _save(fbo, size: tuple[int, int], path: Path) -> None:
    from PIL import Image

    w, h = size
    big = np.frombuffer(fbo.read(components=3), np.uint8).reshape(2 * h, 2 * w, 3)[::-1].astype(np.float64)
    img = big.reshape(h, 2, w, 2, 3).mean(axis=(1, 3)).round().astype(np.uint8)
    Image.fromarray(img).save(path, compress_level=1)


def tree_and_ground(rng: np.random.Generator, height: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """A cloud like a sparse SfM of a tree on flat ground, Z up, root at the origin.

    Returns points (N, 3) and kind (N,) int: 0 ground (a 12 m disc at z = 0), 1 tree (a trunk to
    0.6 ``height`` and a crown ball above it), 2 outliers (far, scattered).
    """
    r = 6.0 * np.sqrt(rng.random(1500))
    a = rng.uniform(0, 2 * np.pi, 1500)
    ground = np.c_[r * np.cos(a), r * np.sin(a), rng.normal(0, 0.01, 1500)]
    z = rng.uniform(0.0, 0.6 * height, 300)
    a = rng.uniform(0, 2 * np.pi, 300)
    trunk = np.c_[0.15 * np.cos(a), 0.15 * np.sin(a), z]
    d = rng.normal(size=(600, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    crown_r = 0.2 * height
    crown = np.array([0.0, 0.0, height - crown_r]) + crown_r * d * rng.random((600, 1)) ** (1 / 3)
    crown[np.argmax(crown[:, 2])] = [0.0, 0.0, height]  # the known top
    far = rng.uniform(-1, 1, (20, 3)) * [12, 12, 3] + [0, 0, 8]
    far[:, :2] += np.sign(far[:, :2]) * 9  # well away from the tree
    pts = np.concatenate([ground, trunk, crown, far])
    kind = np.repeat([0, 1, 1, 2], [len(ground), len(trunk), len(crown), len(far)])
    return pts, kind


def random_similarity(rng: np.random.Generator) -> tuple[float, np.ndarray, np.ndarray]:
    """(scale, rotation (3, 3), translation (3,)) of an arbitrary SfM frame."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return float(rng.uniform(0.1, 3.0)), R, rng.normal(size=3) * 5


def write_colmap_model(folder: Path, points: np.ndarray, eyes: np.ndarray, target: np.ndarray,
                       binary: bool = False, sim: tuple[float, np.ndarray, np.ndarray] | None = None) -> None:
    """A COLMAP model of ``points`` (N, 3) seen by upright cameras at ``eyes`` (V, 3) looking at ``target``
    (Z-up world), moved by the similarity ``sim`` (scale, R, t) if given, written as text or binary."""
    import pycolmap

    from arboretum_client.camera import look_at

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(camera_id=1, model="SIMPLE_PINHOLE", width=320,
                                                    height=240, params=[300.0, 160.0, 120.0]))
    for i, eye in enumerate(np.asarray(eyes, np.float64)):
        R = np.diag([1.0, -1.0, -1.0]) @ look_at(eye, target, [0.0, 0.0, 1.0])[:3, :3]  # y down, z forward
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R), -R @ eye)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=f"view_{i:03d}.png", camera_id=1, image_id=i + 1), pose)
    for p in np.asarray(points, np.float64):
        rec.add_point3D(p, pycolmap.Track(), np.array([120, 90, 60], np.uint8))
    if sim is not None:
        rec.transform(pycolmap.Sim3d(sim[0], pycolmap.Rotation3d(sim[1]), sim[2]))
    folder.mkdir(parents=True, exist_ok=True)
    (rec.write_binary if binary else rec.write_text)(str(folder))
