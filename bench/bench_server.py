"""Server latency on loopback: ping, transform example, remove / merge / split lobe (p95 of many calls).

Starts ``arboretum serve`` as a subprocess on a random port with a temporary library and state, and
drives it with ``arboretum_library.remote.Remote``. Baselines: for ping, a bare pyzmq DEALER/ROUTER echo
in the same process (what the transport alone costs here); for the refinement edits, the same
``decompose.refine`` call made directly in this process (what the algorithm alone costs). Refinement runs on a toy tree of 6,000
points (3 main branches, 10 lobes); every edit is followed by an (unmeasured) undo so each call sees
the same tree.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bench.harness import Row, percentile


def _echo_p95(n: int) -> float:
    import zmq

    ctx = zmq.Context.instance()
    router, dealer = ctx.socket(zmq.ROUTER), ctx.socket(zmq.DEALER)
    for s in (router, dealer):
        s.setsockopt(zmq.LINGER, 0)
    port = router.bind_to_random_port("tcp://127.0.0.1")
    dealer.connect(f"tcp://127.0.0.1:{port}")
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            if router.poll(50):
                router.send_multipart(router.recv_multipart())

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        dealer.send_multipart([b"ping"])
        dealer.recv_multipart()
        times.append(time.perf_counter() - t0)
    stop.set()
    t.join(2)
    router.close(0)
    dealer.close(0)
    return percentile(times, 95)


def _serve(tmp: Path) -> tuple[subprocess.Popen, str]:
    exe = str(Path(sys.executable).with_name("arboretum"))
    proc = subprocess.Popen([exe, "serve", "--bind", "tcp://127.0.0.1:0", "--state", str(tmp / "state"),
                             "--library", str(tmp / "lib")], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True, env=dict(os.environ, OMP_WAIT_POLICY="PASSIVE"))
    if not select.select([proc.stdout], [], [], 30)[0]:
        proc.kill()
        raise RuntimeError("server did not start")
    return proc, proc.stdout.readline().split()[-1]


def _wait_ready(remote, limit_s: float = 120.0) -> None:
    """Steady state: wait until the server has imported its heavy modules (Pong.ready)."""
    from arboretum_library import protocol as P

    t0 = time.perf_counter()
    while not remote.call(P.Ping()).ready:
        if time.perf_counter() - t0 > limit_s:
            raise RuntimeError("server did not finish warming up")
        time.sleep(0.2)


def _times(fn, n: int, after=None) -> list[float]:
    out = []
    for i in range(n):
        t0 = time.perf_counter()
        fn(i)
        out.append(time.perf_counter() - t0)
        if after is not None:
            after()
    return out


def _row(name: str, times: list[float], target: float, **kw) -> Row:
    return Row(name, percentile(times, 95), "s", target, len(times), note="p95 of the calls",
               extra={"median_s": percentile(times, 50), "max_s": max(times)}, **kw)


def run() -> list[Row]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from arboretum_library import protocol as P
    from arboretum_library.geometry import make_transform
    from arboretum_library.remote import Remote
    from arboretum_library.store import Library
    from arboretum_server.decompose.toytree import toy_scan, toy_truth
    from factories import make_example

    rows = []
    with tempfile.TemporaryDirectory() as tmp_:
        tmp = Path(tmp_)
        rng = np.random.default_rng(0)
        with Library.open(tmp / "lib", create=True) as lib:
            for i in range(6):
                lib.add(make_example(rng, id=f"ex-{i}", n_lobes=5))
        proc, endpoint = _serve(tmp)
        try:
            with Remote(endpoint, timeout=60) as r:
                _wait_ready(r)
                sid = r.new_session().session
                for i in range(6):
                    r.add_example(sid, f"ex-{i}", make_transform(t=[i * 0.5, 0, 0]))
                echo = _echo_p95(1000)
                rows.append(_row("ping", _times(lambda i: r.call(P.Ping()), 1000), 0.002,
                                 baseline="bare pyzmq DEALER/ROUTER echo p95", ratio=None))
                rows[-1].ratio = rows[-1].median / echo
                rows.append(_row("transform example (6 placed, recombination on)", _times(
                    lambda i: r.transform_example(sid, "ex-3#1", make_transform(t=[1.5, 0.01 * (i % 7), 0])), 300), 0.02))
                pts, labels = toy_scan(toy_truth(), n=6000)
                r.call(P.RefineOpen(session=sid, points=pts, labels=labels, options={"n_main": 3, "n_lobes": 10}),
                       timeout=120)
                undo = lambda: r.call(P.RefineUndo(session=sid))  # noqa: E731
                rows.append(_row("remove lobe (6k points, 10 lobes)", _times(
                    lambda i: r.call(P.RemoveLobe(session=sid, lobe=i % 10)), 60, undo), 0.02))
                rows.append(_row("merge lobes", _times(
                    lambda i: r.call(P.MergeLobes(session=sid, lobes=(i % 9, i % 9 + 1))), 60, undo), 0.1))
                cloud = r.call(P.RefinePoints(session=sid))

                def split(i):
                    m = cloud.points[cloud.lobe_of == i % 10]
                    st, sz = P.pack_strokes([m[:2], m[-2:]])
                    r.call(P.SplitLobe(session=sid, lobe=i % 10, stroke_points=st, stroke_sizes=sz))

                rows.append(_row("split lobe", _times(split, 60, undo), 0.1))
        finally:
            proc.kill()
            proc.wait(10)
    _in_process_baselines(rows, pts, labels)
    return rows


def _in_process_baselines(rows: list[Row], pts: np.ndarray, labels: np.ndarray) -> None:
    """The same refinement calls made directly on a Decomposition here: what the algorithm alone costs."""
    from arboretum_server.decompose import refine
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    d = decompose(pts, DecomposeOptions(n_main=3, n_lobes=10), labels=labels)
    lobe_pts = [lb.points for lb in d.hbl.lobes]
    calls = {
        "remove lobe": lambda i: refine.remove_lobe(d, i % 10),
        "merge lobes": lambda i: refine.merge_lobes(d, [i % 9, i % 9 + 1]),
        "split lobe": lambda i: refine.split_lobe(d, i % 10, [lobe_pts[i % 10][:2], lobe_pts[i % 10][-2:]]),
    }
    for row in rows:
        for name, fn in calls.items():
            if row.name.startswith(name):
                base = percentile(_times(fn, 60), 95)
                row.baseline, row.ratio = "the same call in-process, no server (p95)", row.median / base
