"""Session 24 (helper-172): the service warms every compiled loop a refinement runs when it starts
(``dispatch.warm_up``, handlers/refine.py ``WARM``): hullpack, graph, grid, lobes and smooth had no ``warm()``, so
a user's first refinement after a start loaded or compiled them itself (8.9 s of compilation on the toy tree
with numba's cache empty). Each ``warm()`` must compile the dtypes the refinement passes: a refinement after
the warm-up adds no signature (a new one is a second compilation, in the user's edit)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

MODULES = ("hullpack", "graph", "grid", "lobes", "smooth", "tetloops", "merge", "similarity")
"""The modules whose compiled loops the refinement runs (the first five had no ``warm()`` before)."""

SCRIPT = r'''
import importlib, json, sys
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
import numpy as np

def signatures():
    out = {}
    for m in MODULES:
        mod = importlib.import_module("arboretum_server.decompose." + m)
        for name, obj in vars(mod).items():
            if hasattr(obj, "signatures") and getattr(obj, "py_func", None) is not None \
                    and obj.py_func.__module__ == mod.__name__:
                out[m + "." + name] = sorted(str(s) for s in obj.signatures)
    return out

if __name__ == "__main__":
    from arboretum_server.service.dispatch import warm_up
    from arboretum_server.service.jobs import call_target
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    warm_up()
    warmed = signatures()
    pts, _ = toy_scan(toy_truth(), n=12000, seed=1)
    kwargs = {"points": pts, "labels": None, "species": "unknown", "options": {}}
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:  # as the service's job workers
        d = pool.submit(call_target, "arboretum_server.service.handlers.refine:decompose_job", kwargs,
                        slice).result()["states"][0]
    from arboretum_library.errors import InputError
    from arboretum_server.decompose import refine
    j = int(np.argmax([len(lb.members) for lb in d.lobes]))
    m = d.lobes[j].members
    ran = []
    for off in range(8):  # 5 strokes spread along the biggest lobe's members, until a set splits it
        pick = m[(np.linspace(0, len(m) - 1, 5).round().astype(int) + off) % len(m)]
        try:
            refine.split_lobe(d, j, [d.to_output(d.points[p])[None] for p in pick])
            ran.append("split")
            break
        except InputError:
            continue
    for name, edit in [("merge", lambda: refine.merge_lobes(d, [0, 1])), ("remove", lambda: refine.remove_lobe(d, 2)),
                       ("insert", lambda: refine.insert_lobe(d, np.flatnonzero(d.lobe_of == 3)[::2]))]:
        try:
            edit()
            ran.append(name)
        except InputError:
            pass
    print(json.dumps({"warmed": warmed, "after": signatures(), "ran": ran}))
'''.replace("MODULES", repr(MODULES))


@pytest.fixture(scope="module")
def warmed_then_refined(tmp_path_factory):
    """(signatures after warm_up, signatures after refinement edits, edits that ran), from a fresh
    process that warms up, has a worker process decompose the toy tree (as the service's job workers do),
    then edits that decomposition itself."""
    script = tmp_path_factory.mktemp("warm") / "warm_then_refine.py"
    script.write_text(SCRIPT)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    return r["warmed"], r["after"], r["ran"]


def test_warm_up_compiles_every_loop_of_the_refinement_modules(warmed_then_refined):
    warmed, _, _ = warmed_then_refined
    for m in MODULES:
        assert any(k.startswith(m + ".") for k in warmed), m  # every module has compiled loops
    cold = sorted(k for k, s in warmed.items() if not s)
    assert cold == [], cold
    assert len(warmed) >= 27  # hullpack 10, graph 4, grid 1, lobes 4, smooth 1, tetloops 5, merge 1, similarity 1


def test_a_refinement_after_warm_up_compiles_nothing_new(warmed_then_refined):
    warmed, after, ran = warmed_then_refined
    assert ran == ["split", "merge", "remove", "insert"]
    new = {k: [s for s in after[k] if s not in warmed.get(k, [])] for k in after}
    assert {k: v for k, v in new.items() if v} == {}
    assert sorted(after) == sorted(warmed)


def test_a_hull_query_compiles_one_kind_of_box():
    # the boxes come read only from clear._packed and writable from callers with their own; numba compiled
    # _inside_any_kernel once per kind (two signatures in one refinement), now the wrapper passes one kind
    from arboretum_server.decompose import hullpack

    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    pack = hullpack.join_packs([hullpack.pack_hull(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))])
    lo, hi = np.full((1, 3), -1.0), np.full((1, 3), 2.0)
    q = np.array([[0.1, 0.1, 0.1], [0.9, 0.9, 0.9], [0.2, 0.2, -0.5]])
    ro = [a.copy() for a in (lo, hi)]
    for a in ro:
        a.flags.writeable = False
    got = [hullpack.inside_any(pack, *box, -1, q) for box in ((lo, hi), ro)]
    assert [g[0].tolist() for g in got] == [[True, False, False]] * 2
    assert [g[1] for g in got] == [3, 3]
    assert len({str(s) for s in hullpack._inside_any_kernel.signatures}) == 1
    assert lo.flags.writeable  # the caller's array is left as it was
