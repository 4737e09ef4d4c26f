"""``arboretum serve`` as a subprocess: SIGKILL in the middle of a job loses nothing committed."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from arboretum_library import protocol as P
from arboretum_library.geometry import make_transform
from arboretum_library.remote import Remote, RemoteError
from arboretum_library.store import Library
from factories import make_example

pytestmark = pytest.mark.timeout(180)
ARBORETUM = str(Path(sys.executable).with_name("arboretum"))


def start(tmp: Path, request) -> tuple[subprocess.Popen, str]:
    """A server on a random loopback port; killed by a finalizer whatever happens."""
    env = dict(os.environ, OMP_WAIT_POLICY="PASSIVE")
    proc = subprocess.Popen(
        [ARBORETUM, "serve", "--bind", "tcp://127.0.0.1:0", "--state", str(tmp / "state"),
         "--library", str(tmp / "lib"), "--workers", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env, text=True,
    )
    request.addfinalizer(lambda: (proc.kill(), proc.wait(10)))
    ready, _, _ = select.select([proc.stdout], [], [], 30)
    assert ready, "server did not start within 30 s"
    line = proc.stdout.readline().strip()
    assert line.startswith("listening on tcp://127.0.0.1:"), line
    return proc, line.split()[-1]


def test_sigkill_during_a_job_loses_no_committed_edit(tmp_path, request):
    rng = np.random.default_rng(11)
    with Library.open(tmp_path / "lib", create=True) as lib:
        for i in range(3):
            lib.add(make_example(rng, id=f"ex-{i}", n_lobes=3))
    proc, endpoint = start(tmp_path, request)
    with Remote(endpoint, timeout=10) as r:
        sid = r.new_session("crash").session
        r.add_example(sid, "ex-0")
        r.add_example(sid, "ex-1", make_transform(t=[3, 0, 0]))
        for i in range(100):  # more than one snapshot's worth of journal
            last = r.transform_example(sid, "ex-1#1", make_transform(t=[3, i * 0.01, 0]))
        r.undo(sid)
        last = r.redo(sid)
    from arboretum_server.decompose.toytree import toy_scan, toy_truth

    pts, labels = toy_scan(toy_truth(), n=5000)
    events: list = []

    def job():
        with Remote(endpoint, timeout=10, retries=0) as r2:
            try:
                r2.call(P.LibraryImport(points=pts, labels=labels, name="toy", options={"n_main": 3, "n_lobes": 6, "points": 5000}),
                        progress=lambda *a: events.append(a))
            except RemoteError:
                pass

    t = threading.Thread(target=job, daemon=True)
    t.start()
    deadline = time.monotonic() + 60
    while not events and time.monotonic() < deadline:
        time.sleep(0.05)
    assert events, "the job never reported progress"
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    t.join(20)

    with Library.open(tmp_path / "lib") as lib:  # reconciles whatever the job left half done
        ids = lib.ids()
        assert {"ex-0", "ex-1", "ex-2"} <= set(ids)
        for i in ids:
            assert lib.get(i).id == i
    proc2, endpoint2 = start(tmp_path, request)
    with Remote(endpoint2, timeout=10) as r:
        a = r.assembly(sid)
        assert a.revision == last.revision == 104 and a.can_undo and not a.can_redo
        placed = {p.instance: p for p in a.assembly.placements}
        assert sorted(placed) == ["ex-0#1", "ex-1#1"]
        assert np.allclose(placed["ex-1#1"].T_world_example[:3, 3], [3, 0.99, 0])
        assert r.undo(sid).revision == 105
        assert r.library_list()[0]["id"] == sorted(ids)[0]
    proc2.send_signal(signal.SIGTERM)
    assert proc2.wait(20) == 0
