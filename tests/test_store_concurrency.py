"""Several reader processes search and load while one writer process adds 50 examples.

Run as a script this file is a reader (``python test_store_concurrency.py read LIB N``) or the writer
(``python test_store_concurrency.py write LIB N``). A reader prints one JSON line with what it saw.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
N = 50


def expected(i: int):
    from factories import make_example

    return make_example(np.random.default_rng(1000 + i), id=f"ex-{i:03d}", n_lobes=i % 8, curved=bool(i % 2))


def _write(path: str, n: int) -> None:
    from arboretum_library.store import Library

    with Library.open(path, fsync=True) as lib:
        for i in range(n):
            lib.add(expected(i))
            time.sleep(0.01)  # the batch builder does work between adds


def _read(path: str, n: int) -> dict:
    """Poll until ``n`` examples are listed; every example seen must load whole and equal."""
    from arboretum_library.store import Library
    from factories import assert_examples_equal

    seen: set[str] = set()
    counts, errors, reads = [], [], 0
    deadline = time.monotonic() + 25
    print("ready", flush=True)
    with Library.open(path, readonly=True) as lib:
        while len(seen) < n and time.monotonic() < deadline:
            try:
                hits = [h.id for h in lib.search("dense sparse straight curved apple")]
                ids = lib.ids()
                counts.append(len(ids))
                if not set(hits) <= set(ids):
                    errors.append(f"search listed {set(hits) - set(ids)} not in ids")
                for id_ in ids:
                    if id_ not in seen:
                        assert_examples_equal(lib.get(id_), expected(int(id_[3:])))
                        seen.add(id_)
                    reads += 1
            except Exception as exc:  # any failure is reported, not raised
                errors.append(f"{type(exc).__name__}: {exc}")
    return {"seen": len(seen), "distinct_counts": len(set(counts)), "reads": reads, "errors": errors[:5]}


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    mode, lib_path, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
    if mode == "write":
        _write(lib_path, count)
    else:
        print(json.dumps(_read(lib_path, count)), flush=True)
    raise SystemExit(0)

from arboretum_library.store import Library  # noqa: E402


def test_readers_see_only_whole_examples_while_a_writer_adds(tmp_path):
    root = tmp_path / "lib"
    Library.open(root, create=True).close()
    env = {**os.environ, "PYTHONPATH": str(HERE)}
    cmd = [sys.executable, __file__]
    readers = [subprocess.Popen([*cmd, "read", str(root), str(N)], stdout=subprocess.PIPE, env=env)
               for _ in range(2)]
    for r in readers:
        assert r.stdout.readline().strip() == b"ready"
    writer = subprocess.run([*cmd, "write", str(root), str(N)], env=env, capture_output=True, timeout=60)
    assert writer.returncode == 0, writer.stderr.decode()[-2000:]
    reports = [json.loads(r.communicate(timeout=60)[0]) for r in readers]
    for rep in reports:
        assert rep["errors"] == []
        assert rep["seen"] == N
        assert rep["distinct_counts"] >= 3, rep  # it really read while the writer was adding
    with Library.open(root) as lib:
        assert len(lib) == N
        assert lib.recovered.reindexed == [] and lib.recovered.cleaned == 0
