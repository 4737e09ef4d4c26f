"""Two processes saving kernels at once cannot cross them (session 29): numba's own layout numbers a kernel's
data files in save order, so two versions saved at once can leave the index naming one and the file holding
the other. ``jitcache.KeyedCacheFile`` names a data file by its key, writes it before the index names it and
updates the index under a lock. The interleaving is forced here with threads on two cache-file objects of one
folder, as two processes would hold them."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

from arboretum_server import jitcache

SERVER = Path(jitcache.__file__).parent
WAIT = 0.5  # seconds a step waits for the other side; the keyed layout's lock makes some waits time out

KEY_A = (("float64", "int64"), ("x86_64", "generic"), ("code", "cells"))
KEY_B = (("float64", "Literal[int](0)"), ("x86_64", "generic"), ("code", "cells"))


def _gated(cls: type) -> type:
    """``cls`` with its steps ordered as the worst case for numba's layout: both read the empty index, B
    writes its index, then A its index, then A its data, then B its data."""

    class Gated(cls):
        def __init__(self, *args, side: str, gates: dict, **kwargs):
            super().__init__(*args, **kwargs)
            self.side, self.gates = side, gates

        def _load_index(self):
            out = super()._load_index()
            try:
                self.gates["read"].wait(WAIT)
            except threading.BrokenBarrierError:
                pass
            return out

        def _save_index(self, overloads):
            if self.side == "A":
                self.gates["B index"].wait(WAIT)
            super()._save_index(overloads)
            if self.side == "B":
                self.gates["B index"].set()

        def _save_data(self, name, data):
            if self.side == "B":
                self.gates["A data"].wait(WAIT)
            super()._save_data(name, data)
            if self.side == "A":
                self.gates["A data"].set()

    return Gated


def _race(cls: type, folder: Path) -> tuple[object, object]:
    """Save version A and version B of one kernel from two threads, then load both in a fresh object."""
    gates = {"read": threading.Barrier(2), "B index": threading.Event(), "A data": threading.Event()}
    gated = _gated(cls)
    made = {side: gated(cache_path=str(folder), filename_base="kernel-12.py311", source_stamp=(1.0, 100),
                        side=side, gates=gates) for side in "AB"}
    threads = [threading.Thread(target=made["A"].save, args=(KEY_A, "machine code A")),
               threading.Thread(target=made["B"].save, args=(KEY_B, "machine code B"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    fresh = cls(cache_path=str(folder), filename_base="kernel-12.py311", source_stamp=(1.0, 100))
    return fresh.load(KEY_A), fresh.load(KEY_B)


def test_numbas_own_layout_crosses_two_versions_saved_at_once(tmp_path):
    """Why KeyedCacheFile exists: the stock class hands version A's key version B's code."""
    from numba.core import caching

    stock = jitcache._INSTALLED[0].__mro__[1] if jitcache._INSTALLED else caching.IndexDataCacheFile
    assert stock.__name__ == "IndexDataCacheFile"
    a, b = _race(stock, tmp_path)
    assert a == "machine code B"  # crossed: the index says file 1 for A, B wrote file 1 last
    assert b is None  # B's index entry was overwritten: compiled again, harmless


def test_keyed_files_keep_each_version_with_its_own_key(tmp_path):
    keyed = jitcache.install()
    a, b = _race(keyed, tmp_path)
    assert (a, b) == ("machine code A", "machine code B")
    names = sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".nbc")
    assert names == sorted(f"kernel-12.py311.k{jitcache.key_tag(k)[:24]}.nbc" for k in (KEY_A, KEY_B))


def test_a_file_holding_another_key_is_not_loaded(tmp_path):
    keyed = jitcache.install()
    f = keyed(cache_path=str(tmp_path), filename_base="kernel-12.py311", source_stamp=(1.0, 100))
    f.save(KEY_A, "machine code A")
    f.save(KEY_B, "machine code B")
    (tmp_path / f._keyed_name(KEY_A)).write_bytes((tmp_path / f._keyed_name(KEY_B)).read_bytes())
    assert f.load(KEY_A) is None and f.load(KEY_B) == "machine code B"
    (tmp_path / f._keyed_name(KEY_B)).write_bytes(b"truncated")
    assert f.load(KEY_B) is None


RUN = """
import importlib, json, numba
from numba.core import caching
names = ["decompose.graph", "decompose.lobes", "decompose.hullpack", "decompose.tetloops", "decompose.similarity",
         "decompose.merge", "decompose.grid", "decompose.smooth", "synth.kernels", "modules.pairing"]
kernels = [v for n in names for v in vars(importlib.import_module("arboretum_server." + n)).values()
           if isinstance(v, numba.core.registry.CPUDispatcher) and v.__module__ == "arboretum_server." + n
           and type(v._cache).__name__ == "FunctionCache"]
print(json.dumps({"class": caching.IndexDataCacheFile.__name__, "kernels": len(kernels),
                  "keyed": sum(type(k._cache._cache_file).__name__ == "KeyedCacheFile" for k in kernels)}))
"""


def test_every_server_kernel_is_cached_through_the_keyed_files():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SERVER.parent), str(SERVER.parent.parent / "library")]))
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["class"] == "KeyedCacheFile"
    assert seen["kernels"] >= 40 and seen["keyed"] == seen["kernels"]
    direct = [str(p.relative_to(SERVER)) for p in sorted(SERVER.rglob("*.py"))
              if re.search(r"^\s*(from numba import|import numba\s*$)", p.read_text(), re.M) and p.name != "jitcache.py"]
    assert direct == []  # a kernel compiled with numba's own njit would skip the keyed files


KERNEL = """from arboretum_server.jitcache import njit


@njit(cache=True)
def f(x, n):
    s = 0.0
    for i in range(n, x.size):
        s += x[i] * (i + 1)
    return s + n


@njit(cache=True)
def g(x):
    return f(x, 0)  # numba compiles f apart for Literal[int](0) here
"""
USE = """import json, numpy as np, kern
x = np.arange(10.0)
print(json.dumps({"f": kern.f(x, 3), "g": kern.g(x), "hits": sum(kern.f.stats.cache_hits.values())
                  + sum(kern.g.stats.cache_hits.values())}))
"""


def test_keyed_kernels_load_back_in_another_process(tmp_path):
    (tmp_path / "kern.py").write_text(KERNEL)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(SERVER.parent), str(SERVER.parent.parent / "library")]))
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", USE], env=env, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    due = {"f": float(sum(i * (i + 1) for i in range(3, 10)) + 3), "g": float(sum(i * (i + 1) for i in range(10)))}
    assert [{k: r[k] for k in due} for r in runs] == [due, due]
    assert (runs[0]["hits"], runs[1]["hits"]) == (0, 2)  # the second process compiles nothing
    files = [p.name for p in (tmp_path / "cache").rglob("kern.*.nbc")]
    assert len(files) == 3 and all(re.search(r"\.k[0-9a-f]{24}\.nbc$", n) for n in files)  # f twice, g once


def test_an_unknown_numba_layout_is_left_alone():
    from numba.core import caching

    stock = jitcache.install().__mro__[1]
    assert jitcache.layout_known(stock) and jitcache.layout_known(caching.IndexDataCacheFile)

    class Renamed(stock):  # a numba that renamed its data-file pattern
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self._data_name_pattern = kwargs["filename_base"] + "-{n}.nbc"

    class Missing:  # a numba whose cache file has another interface
        def __init__(self, cache_path, filename_base, source_stamp):
            self._index_path = cache_path

    assert not jitcache.layout_known(Renamed) and not jitcache.layout_known(Missing)


def test_a_folder_removed_or_an_index_damaged_costs_a_compile_not_a_failure(tmp_path):
    keyed = jitcache.install()
    folder = tmp_path / "kernels"
    folder.mkdir()
    f = keyed(cache_path=str(folder), filename_base="kernel-12.py311", source_stamp=(1.0, 100))
    f.save(KEY_A, "machine code A")
    assert f.load(KEY_A) == "machine code A"
    (folder / "kernel-12.py311.nbi").write_bytes(b"\x80\x04truncated")  # a damaged index
    assert f.load(KEY_A) is None
    f.save(KEY_B, "machine code B")  # written again from an empty index
    assert (f.load(KEY_A), f.load(KEY_B)) == (None, "machine code B")
    for p in folder.iterdir():  # another process pruned the folder
        p.unlink()
    folder.rmdir()
    f.save(KEY_A, "machine code A")  # numba would raise FileNotFoundError inside the compile
    assert f.load(KEY_A) is None and not folder.exists()


CLOSURES = """import numpy as np
from {njit_from} import njit


def make(k):
    @njit
    def inner(x):
        s = 0
        for i in range(x.shape[0]):
            s += (x[i] * k) % 7 + k
        return s
    return inner


inner1, inner2 = make(1), make(2)  # one name, make.<locals>.inner, two bodies


@njit(cache=True)
def outer1(x):
    return inner1(x)


@njit(cache=True)
def outer2(x):
    return inner2(x)
"""
CALL = """import json, sys, numpy as np, cmod
x = np.arange(10, dtype=np.int64)
print(json.dumps([int(getattr(cmod, n)(x)) for n in sys.argv[1:]]))
"""


def _closures(tmp_path: Path, njit_from: str) -> list[list[int]]:
    """Compile outer1 and outer2 in two processes (from an empty cache), then load both in a third, in both
    orders: the answers of each process."""
    (tmp_path / "cmod.py").write_text(CLOSURES.format(njit_from=njit_from))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(SERVER.parent), str(SERVER.parent.parent / "library")]))
    answers = []
    for names in (["outer1"], ["outer2"], ["outer1", "outer2"], ["outer2", "outer1"]):
        out = subprocess.run([sys.executable, "-c", CALL, *names], env=env, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        answers.append(json.loads(out.stdout.strip().splitlines()[-1]))
    return answers


def test_numbas_counted_names_cross_two_closures_cached_by_two_processes(tmp_path):
    """Why RandomUids exists: each process counts from 1, so both name their closure make.<locals>.inner
    number 2; the process that loads both runs the first body loaded for both kernels."""
    assert _closures(tmp_path, "numba") == [[34], [47], [34, 34], [47, 47]]


def test_random_numbers_keep_each_closure_its_body(tmp_path):
    assert _closures(tmp_path, "arboretum_server.jitcache") == [[34], [47], [34, 47], [47, 34]]


def test_random_uids_are_unique_and_long():
    uids = jitcache.RandomUids()
    drawn = [next(uids) for _ in range(2000)]
    assert len(set(drawn)) == 2000 and min(drawn) >= 1 << jitcache.UID_BITS
    from numba.core import bytecode

    jitcache.install()
    assert isinstance(bytecode.FunctionIdentity._unique_ids, jitcache.RandomUids)
