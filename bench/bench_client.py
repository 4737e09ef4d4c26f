"""Client frame cost: the CPU work to prepare a frame of a full tree with the geometry already uploaded.

The scene is bench_render's full tree (2,500 branch tubes, ~1.04M triangles; 20,000 instanced leaves;
1,000 instanced modules) uploaded into an App's renderer (EGL, 1280x720), with the side panel and
status bar on and both hands idle. Rows:
- ``App.update`` alone (input, hands, tools, network drain, change checks, highlight): the app's own
  per-frame Python, independent of the scene size;
- ``App.update`` + ``Renderer.issue`` with the same draw calls on tiny geometry: the whole per-frame CPU
  cost of app and renderer (the issue's 2 ms target);
- the same with the full geometry: on llvmpipe the vertex stage runs inside each draw call on the calling
  thread, so this measures the software rasteriser's vertex work, not our Python;
- baseline: a frame that rebuilds and re-uploads the scene (what a naive loop would do every frame) for
  a small six-example assembly.
"""

from __future__ import annotations

import statistics
import tempfile
import time

import numpy as np

from bench.bench_render import SIZE, build_scene
from bench.harness import Row


def _times(fn, runs: int) -> float:
    fn()
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return statistics.median(out)


def _app(renderer):
    from arboretum_client.app import App
    from arboretum_client.session_fake import FakeSession

    app = App(renderer, FakeSession, out_dir=tempfile.mkdtemp())
    app.start()
    for k, ex in enumerate(("oak-0001", "oak-0002", "oak-0003", "pine-0001", "pine-0002", "pine-0003")):
        T = np.eye(4)
        T[:3, 3] = (1.2 * (k % 3), 1.2 * (k // 3), 0.0)
        app.actions.add_example(ex, T)
    app.worker.wait_idle(30)
    app.update()
    return app


def _issue(app, camera, runs: int = 9) -> float:
    """Median seconds of ``App.update`` + ``Renderer.issue``, the GPU idle before each run (not timed)."""
    r, out = app.renderer, []
    for _ in range(runs + 1):
        r.ctx.finish()
        t0 = time.perf_counter()
        app.update()
        r.issue(camera)
        out.append(time.perf_counter() - t0)
        r.resolve()
    r.ctx.finish()
    return statistics.median(out[1:])


def run() -> list[Row]:
    from arboretum_client.context import create_headless_context
    from arboretum_client.render.renderer import Renderer

    ctx = create_headless_context()
    r = Renderer(ctx, SIZE)
    app = _app(r)
    rebuild = _times(lambda: (app.state.touch_scene(), app.update(), r.issue(app.desktop.camera), r.ctx.finish()), 5)
    full, cam = build_scene(np.random.default_rng(0))
    tiny, _ = build_scene(np.random.default_rng(0), tiny=True)
    r.upload(full)
    app.update()
    update = _times(app.update, 50)
    full_issue = _issue(app, cam)
    stats = r.stats
    extra = {"draw_calls": stats.draw_calls, "triangles": stats.triangles, "leaves": 20_000, "modules": 1000,
             "renderer": ctx.info["GL_RENDERER"], "size": list(SIZE)}
    r.upload(tiny)
    tiny_issue = _issue(app, cam)
    app.close()
    r.release()
    assert ctx.error == "GL_NO_ERROR", ctx.error
    ctx.release()
    note = "provisional: 2 shared cores, loaded by other jobs"
    return [
        Row("client: App.update per frame (geometry uploaded, hands idle)", update * 1e3, "ms", target=2.0, runs=50,
            note=note, extra=extra),
        Row("client: prepare frame CPU = App.update + Renderer.issue (same draw calls, tiny geometry)",
            tiny_issue * 1e3, "ms", target=2.0, runs=9, baseline="rebuild + re-upload the scene every frame "
            "(6-example assembly)", ratio=tiny_issue / rebuild, note=note, extra={"draw_calls": stats.draw_calls}),
        Row("client: App.update + Renderer.issue, full tree on llvmpipe (vertex work on this thread)",
            full_issue * 1e3, "ms", runs=9, note=note, extra=extra),
        Row("client: baseline frame that rebuilds the scene (6 examples)", rebuild * 1e3, "ms", runs=5, note=note),
    ]
