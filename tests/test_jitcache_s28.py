"""The kernel cache is keyed by every kernel source (session 28): numba checks a cached kernel against its
own file only, so a kernel calling one from an edited file kept the old code."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from arboretum_server import jitcache

SERVER = Path(jitcache.__file__).parent

CALLEE = "from numba import njit\n\n\n@njit(cache=True)\ndef f():\n    return {value}\n"
CALLER = "from numba import njit\n\nfrom .a import f\n\n\n@njit(cache=True)\ndef g():\n    return f() + 0.5\n"
INIT = ("from pathlib import Path\n\nfrom arboretum_server import jitcache\n\n"
        "CACHE = jitcache.use(Path(__file__).parent)\n")
RUN = ("import json, pkgx, pkgx.b as b\nv = b.g()\n"
       "print(json.dumps({'value': v, 'hits': sum(b.g.stats.cache_hits.values()), 'cache': str(pkgx.CACHE)}))\n")


def _package(root: Path, value: float) -> Path:
    pkg = root / "pkgx"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text(INIT)
    (pkg / "a.py").write_text(CALLEE.format(value=value))
    (pkg / "b.py").write_text(CALLER)
    return pkg


def _run(root: Path, base: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), str(SERVER.parent)]),
               NUMBA_CACHE_DIR=str(base))
    out = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_callee_edited_in_another_file_is_compiled_again(tmp_path):
    base = tmp_path / "cache"
    _package(tmp_path, 1.0)
    first, again = _run(tmp_path, base), _run(tmp_path, base)
    assert (first["value"], again["value"]) == (1.5, 1.5)
    assert (first["hits"], again["hits"]) == (0, 1)  # the second run loads g from the cache
    _package(tmp_path, 2.0)  # only a.py changes: numba's own check of b.py's cache passes
    edited = _run(tmp_path, base)
    assert edited["value"] == 2.5 and edited["hits"] == 0
    assert edited["cache"] != first["cache"] and Path(edited["cache"]).parent == base


def test_the_digest_reads_kernel_sources_only(tmp_path):
    pkg = _package(tmp_path, 1.0)
    before = jitcache.kernel_digest(pkg)
    (pkg / "plain.py").write_text("X = 1\n")  # no numba in it: not a kernel source
    assert jitcache.kernel_digest(pkg) == before
    (pkg / "b.py").write_text(CALLER + "\n# numba\n")
    assert jitcache.kernel_digest(pkg) != before and len(before) == 16


def test_the_folder_nests_under_a_given_base_and_a_child_keeps_it(tmp_path):
    pkg = _package(tmp_path, 1.0)
    here = jitcache.cache_dir(pkg, tmp_path / "base")
    assert here == tmp_path / "base" / (jitcache.PREFIX + jitcache.kernel_digest(pkg))
    assert jitcache.cache_dir(pkg, here) == here  # a child process inherits the folder as NUMBA_CACHE_DIR
    stale = tmp_path / "base" / (jitcache.PREFIX + "0" * 16)
    assert jitcache.cache_dir(pkg, stale) == here


def test_old_folders_are_pruned_to_the_newest(tmp_path):
    olds = []
    for i in range(5):
        p = tmp_path / f"{jitcache.PREFIX}{i:016x}"
        p.mkdir()
        os.utime(p, (time.time() - 100 * (5 - i),) * 2)  # 0 oldest, 4 newest
        olds.append(p)
    current = tmp_path / f"{jitcache.PREFIX}{'f' * 16}"
    current.mkdir()
    (tmp_path / "other").mkdir()
    gone = jitcache.prune(current, keep=3)
    assert sorted(p.name for p in gone) == [p.name for p in olds[:3]]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([current.name, olds[3].name, olds[4].name, "other"])
