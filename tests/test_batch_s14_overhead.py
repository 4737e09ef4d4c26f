"""``library build`` (session 14): a LocalCluster worker freezes the garbage collector's view of its
heap after its first scan (``tasks._freeze_once``), which cut the close of the cluster from ~1 s to
0.1 s; a build's examples stay exactly those of a serial decomposition of the same scans."""

from __future__ import annotations

import gc
import subprocess
import sys
from pathlib import Path

import numpy as np

from arboretum_library.codec import flatten
from arboretum_library.store import Library
from arboretum_server.batch.build import BuildOptions, _Cluster, build_library, species_for
from arboretum_server.batch.synthetic import synthetic_scans
from arboretum_server.batch.tasks import decompose_scan
from arboretum_server.decompose.examples import file_sha256

POINTS = 1500


def _gc_state() -> dict:
    from arboretum_server.batch import tasks

    return {"count": gc.get_freeze_count(), **getattr(tasks, "_GC", {})}


def test_local_workers_freeze_the_heap_after_their_first_scan(tmp_path):
    scan = str(synthetic_scans(tmp_path, 1, points=POINTS)[0])
    with _Cluster(BuildOptions(workers=1)) as (client, _, _):
        before = next(iter(client.run(_gc_state).values()))
        out = client.submit(decompose_scan, scan, "", {"species": species_for(scan, None), "points": POINTS},
                            pure=False).result()
        after = next(iter(client.run(_gc_state).values()))
        again = client.submit(decompose_scan, scan, "", {"species": species_for(scan, None), "points": POINTS},
                              pure=False).result()
        last = next(iter(client.run(_gc_state).values()))
    assert out.error == "" and again.error == ""
    assert before == {"count": 0, "freeze": True, "frozen": False}
    assert after["count"] > 50_000 and after["frozen"] is True  # the modules decompose imported
    assert last["count"] <= after["count"]  # once: nothing of the second scan is frozen


FREEZE_PROBE = """
import gc, sys
from arboretum_server.batch.tasks import decompose_scan
out = decompose_scan(sys.argv[1], "", {"species": "apple", "points": 1500})
print(out.error == "", gc.get_freeze_count())
"""


def test_decompose_scan_outside_a_worker_leaves_the_collector_alone(tmp_path):
    """A library function: a process that calls it (the bench's serial loop, ``arboretum decompose``)
    keeps its own garbage collection."""
    scan = str(synthetic_scans(tmp_path, 1, points=POINTS)[0])
    done = subprocess.run([sys.executable, "-c", FREEZE_PROBE, scan], capture_output=True, text=True,
                          check=True, timeout=300)
    assert done.stdout.split() == ["True", "0"]


def _arrays(example) -> dict[str, np.ndarray]:
    return flatten(example.structure)[1]


def test_built_examples_equal_a_serial_decomposition(tmp_path):
    scans = synthetic_scans(tmp_path / "scans", 4, points=POINTS)
    result = build_library([str(p) for p in scans], tmp_path / "lib", BuildOptions(workers=2, points=POINTS))
    assert result.count("added") == 4
    with Library.open(tmp_path / "lib", readonly=True) as lib:
        for r in result.records:
            serial = decompose_scan(r.path, file_sha256(r.path), {"species": r.species, "points": POINTS})
            stored = [lib.get(i) for i in r.examples]
            assert len(stored) == len(serial.examples) > 0
            for got, want in zip(stored, serial.examples, strict=True):
                a, b = _arrays(got), _arrays(want)
                assert a.keys() == b.keys()
                for k in a:
                    assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]), (Path(r.path).name, k)
