"""Guiding-vector tree growth at the paper's size: 150,000 graph nodes (Xu and Mould 2015, section 4).

The paper: 9.5 s per tree on a 2.8 GHz desktop (about 6 s for the Yao graph, 2 s for path planning).
The issue's target: graph + paths under 3 s on our 2-core machine. Rows give the graph (Poisson disc
+ Yao graph) and the path planning (all five iterations of the ``default`` preset) separately, median
of 3, for the default 14 sectors and the paper's 8; ``extra`` also gives the median CPU (process) time,
steadier on a shared machine. The numba kernels are warmed up first: the first call of a fresh process
(loading the compiled kernels from ``__pycache__``) and a compile from scratch (a subprocess with an
empty ``NUMBA_CACHE_DIR``) are reported as extras, not counted as tree time.

Baselines, measured in the same run: for the paths, the pure-Python reference search
(``paths.reference_search``) on the same 20k-node tree as the kernel (the 150k reference takes
minutes); for the graph, scipy's cKDTree k-nearest query alone on the same 150k nodes.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from arboretum_server.synth.guiding import build_graph, grow_paths
from arboretum_server.synth.paths import lazy_search, reference_search
from arboretum_server.synth.presets import preset

from .harness import Row

NODES = 150_000
SMALL = 20_000
RUNS = 3
TARGET = 3.0
_WARM = (
    "import time; t = time.perf_counter(); "
    "from arboretum_server.synth.guiding import grow_guiding; "
    "from arboretum_server.synth.presets import preset; "
    "grow_guiding(preset('default', nodes=3000), 0); print(time.perf_counter() - t)"
)


def _first_call(cache_dir: str | None) -> float:
    """Seconds for a fresh process to import and grow a 3k-node tree (cache_dir: a fresh cache)."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run([sys.executable, "-c", _WARM], env=env, capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def _one(nodes: int, sectors: int, search=lazy_search) -> tuple[float, ...]:
    opts = preset("default", nodes=nodes, sectors=sectors)
    rng = np.random.default_rng(1)
    t0, c0 = time.perf_counter(), time.process_time()
    g, root = build_graph(opts, rng)
    t1, c1 = time.perf_counter(), time.process_time()
    st = grow_paths(g, root, opts, rng, search=search)
    t2, c2 = time.perf_counter(), time.process_time()
    return t1 - t0, t2 - t1, c1 - c0, c2 - c1, len(g.points), int(st.in_tree.sum())


def _knn_only(nodes: int, sectors: int) -> float:
    from scipy.spatial import cKDTree

    g, _ = build_graph(preset("default", nodes=nodes, sectors=sectors), np.random.default_rng(1))
    t = time.perf_counter()
    cKDTree(g.points).query(g.points, 25, workers=2)
    return time.perf_counter() - t


def _med(runs, i: int) -> float:
    return statistics.median(r[i] for r in runs)


def run() -> list[Row]:
    with tempfile.TemporaryDirectory() as tmp:
        compile_s = _first_call(tmp)
    first_s = _first_call(None)
    _one(3000, 14)  # warm-up: load the kernels in this process
    rows = []
    for sectors in (14, 8):
        runs = [_one(NODES, sectors) for _ in range(RUNS)]
        small = [_one(SMALL, sectors) for _ in range(RUNS)]
        ref = [_one(SMALL, sectors, reference_search) for _ in range(RUNS)]
        knn = statistics.median(_knn_only(NODES, sectors) for _ in range(RUNS))
        extra = {"graph_nodes": runs[0][4], "tree_nodes": runs[0][5], "sectors": sectors,
                 "cpu_graph_s": _med(runs, 2), "cpu_paths_s": _med(runs, 3),
                 "paths_20k_kernel_s": _med(small, 1), "paths_20k_reference_s": _med(ref, 1),
                 "first_call_cached_s": first_s, "first_call_compiling_s": compile_s}  # fmt: skip
        name = f"guiding tree {NODES // 1000}k nodes, Yao-{sectors}"
        rows += [
            Row(f"{name}: graph (Poisson + Yao)", _med(runs, 0), runs=RUNS, extra=extra,
                baseline="scipy cKDTree 25-nearest query alone (2 workers)",
                ratio=_med(runs, 0) / knn, note="paper: about 6 s (C++, 2015); numba kernels"),
            Row(f"{name}: paths (5 iterations)", _med(runs, 1), runs=RUNS, extra=extra,
                baseline=f"pure-Python reference search, {SMALL // 1000}k-node tree",
                ratio=_med(small, 1) / _med(ref, 1),
                note="paper: about 2 s; ratio = kernel / reference on the 20k tree"),
            Row(f"{name}: graph + paths", statistics.median(r[0] + r[1] for r in runs),
                runs=RUNS, target=TARGET, extra=extra, note="paper: 9.5 s per tree in total"),
        ]  # fmt: skip
    return rows
