"""Renderer cost on EGL/llvmpipe at 1280x720: a scene of ~1M tube triangles, 20k instanced leaf quads
and 1,000 instanced module meshes.

Rows: upload (tube generation + buffers), CPU time to prepare a frame (all draw calls issued, no GPU
wait), a whole frame (+ glFinish), read-back, and as baseline the same 1,000 modules drawn as 1,000
separate meshes (one draw call each) against one instanced call.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from bench.harness import Row, median_time

SIZE = (1280, 720)


def build_scene(rng: np.random.Generator, separate_modules: bool = False, tiny: bool = False):
    """Branch tubes (~1M triangles), 20k leaf quads, 1,000 module spheres; returns (scene, camera).

    ``separate_modules``: the modules as 1,000 plain meshes; ``tiny``: the same batches with 1 tube,
    1 leaf and 1 module (to measure the per-frame overhead)."""
    from arboretum_client.camera import fit_camera
    from arboretum_client.render.meshes import quad, uv_sphere
    from arboretum_client.scene import InstancedMesh, Mesh, Polyline, Scene, grid_for_bounds

    n_lines, n_verts = (1, 26) if tiny else (2500, 26)  # 2500 * 25 segments * 16 triangles = 1.0M triangles (+ caps)
    steps = rng.normal(size=(n_lines, n_verts, 3)) * 0.02 + [0, 0, 0.05]
    starts = rng.uniform(-2, 2, (n_lines, 1, 3)) * [1, 1, 0] + [0, 0, 1]
    paths = starts + np.cumsum(steps, axis=1)
    items = [Polyline(points=p, radii=np.linspace(0.02, 0.005, n_verts), color=(0.4, 0.3, 0.2), pick_id=i + 1)
             for i, p in enumerate(paths)]
    qv, qf = quad()
    items.append(InstancedMesh(mesh=Mesh(vertices=qv, faces=qf, color=(0.3, 0.6, 0.2), pick_id=9001),
                               matrices=_matrices(rng, 1 if tiny else 20_000, 0.05)))
    sv, sf = uv_sphere(12, 16)
    mods = _matrices(rng, 1 if tiny else 1000, 0.08)
    if separate_modules:
        items += [Mesh(vertices=sv @ (M[:3, :3].T) + M[:3, 3], faces=sf, color=(0.5, 0.4, 0.3), pick_id=9002)
                  for M in mods]
    else:
        items.append(InstancedMesh(mesh=Mesh(vertices=sv, faces=sf, color=(0.5, 0.4, 0.3), pick_id=9002),
                                   matrices=mods))
    scene = Scene(items=tuple(items))
    scene = Scene(items=scene.items, grid=grid_for_bounds(scene.bounds()))
    return scene, fit_camera(scene.bounds(), "iso", SIZE[0] / SIZE[1])


def _matrices(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """(n, 4, 4) random rotations about Z, uniform ``scale``, positions in a 4 x 4 x 3 m crown."""
    a = rng.uniform(0, 2 * np.pi, n)
    M = np.tile(np.eye(4), (n, 1, 1))
    M[:, 0, 0], M[:, 0, 1], M[:, 1, 0], M[:, 1, 1] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    M[:, :3, :3] *= scale
    M[:, :3, 3] = rng.uniform([-2, -2, 1.5], [2, 2, 4.5], (n, 3))
    return M


def run() -> list[Row]:
    from arboretum_client.context import create_headless_context
    from arboretum_client.render.renderer import Renderer

    ctx = create_headless_context()
    r = Renderer(ctx, SIZE)
    scene, cam = build_scene(np.random.default_rng(0))
    t0 = time.perf_counter()
    r.upload(scene)
    upload = time.perf_counter() - t0
    prepare = prepare_time(r, cam, runs=5)
    frame = median_time(lambda: (r.render(cam), ctx.finish()), runs=5)
    readback = median_time(r.read, runs=5)
    stats = r.stats
    extra = {"draw_calls": stats.draw_calls, "triangles": stats.triangles, "size": list(SIZE),
             "renderer": ctx.info["GL_RENDERER"], "samples": r.samples}
    r.upload(build_scene(np.random.default_rng(0), tiny=True)[0])
    overhead = prepare_time(r, cam, runs=20)
    naive_scene, _ = build_scene(np.random.default_rng(0), separate_modules=True)
    r.upload(naive_scene)
    naive_prepare = prepare_time(r, cam, runs=3)
    naive_calls = r.stats.draw_calls
    r.release()
    assert ctx.error == "GL_NO_ERROR", ctx.error
    ctx.release()
    note = "provisional: 2 shared cores, loaded by other jobs"
    return [
        Row("render: upload scene (tubes + buffers)", upload, "s", runs=1, note=note, extra=extra),
        Row("render: prepare frame, CPU (draw calls issued)", prepare * 1e3, "ms", runs=5,
            baseline=f"1,000 modules as separate meshes ({naive_calls} draw calls)",
            ratio=prepare / naive_prepare, note=note, extra=extra),
        Row("render: prepare frame, same draw calls, tiny geometry", overhead * 1e3, "ms", runs=20,
            note="the renderer's own CPU cost per frame (Python + GL calls)"),
        Row("render: frame 1280x720 incl. GPU (llvmpipe)", frame * 1e3, "ms", runs=5, note=note, extra=extra),
        Row("render: read back 1280x720 RGBA", readback * 1e3, "ms", runs=5, note=note),
    ]


def prepare_time(r, cam, runs: int) -> float:
    """Median seconds for ``r.issue`` to issue a frame's draw calls, the GPU idle before each run.

    On llvmpipe a draw call runs the vertex stage on the calling thread, so this includes vertex work."""
    times = []
    for _ in range(runs + 1):
        r.ctx.finish()
        t0 = time.perf_counter()
        r.issue(cam)
        times.append(time.perf_counter() - t0)
        r.resolve()
    r.ctx.finish()
    return statistics.median(times[1:])
