"""The server over tcp://127.0.0.1 (random ports, in a thread): malformed input, concurrent clients,
jobs beside edits, cancellation, retries answered once."""

from __future__ import annotations

import threading
import time

import msgpack
import numpy as np
import pytest
import zmq

from arboretum_library import protocol as P
from arboretum_library.geometry import make_transform
from arboretum_library.remote import Remote, RemoteError
from arboretum_library.store import Library
from arboretum_library.wire import PROTOCOL_VERSION, Message, encode
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher, load_handlers
from arboretum_server.service.jobs import Job, JobRunner
from arboretum_server.service.sessions import Sessions
from arboretum_server.service.socket import Server
from factories import make_example, serving

pytestmark = pytest.mark.timeout(120)


def slow_job(progress, seconds: float, steps: int = 20) -> dict:
    """A job for tests: ``steps`` progress events over ``seconds``."""
    for i in range(steps):
        progress(i, steps, f"step {i}")
        time.sleep(seconds / steps)
    progress(steps, steps, "done")
    return {"name": "slow.bin", "data": np.arange(4, dtype=np.uint8), "stats": {"steps": steps}}


def dying_job(progress) -> None:
    import os

    progress(0, 1, "about to die")
    os._exit(3)


def refusing_job(progress) -> None:
    from arboretum_library.errors import InputError

    raise InputError("this scan has no tree in it")


def slow_export(ctx, req: P.ExportMesh) -> Job:
    return Job(f"{__name__}:slow_job", {"seconds": float(req.seed) / 10}, lambda r: P.ExportFile(**r))


@pytest.fixture
def served(tmp_path):
    rng = np.random.default_rng(5)
    with Library.open(tmp_path / "lib", create=True) as lib:
        for i in range(4):
            lib.add(make_example(rng, id=f"ex-{i}", n_lobes=3))
    ctx = Context(Sessions(tmp_path / "state"), tmp_path / "lib")
    handlers = load_handlers()
    handlers[P.ExportMesh] = slow_export
    handlers[P.Grow] = lambda ctx, req: Job(f"{__name__}:dying_job", {}, lambda r: P.Ack())
    handlers[P.ExportModules] = lambda ctx, req: Job(f"{__name__}:refusing_job", {}, lambda r: P.Ack())
    with serving(Server(Dispatcher(ctx, handlers), "tcp://127.0.0.1:0", jobs=JobRunner(2))) as server:
        yield server
    ctx.close()


def raw_socket(server: Server) -> zmq.Socket:
    s = zmq.Context.instance().socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.RCVTIMEO, 5000)
    s.connect(server.endpoint)
    return s


def malformed(rng: np.random.Generator, i: int) -> list[bytes]:
    """One of many kinds of broken message."""
    good = P.to_frames(P.RemoveLobe(session="s", lobe=1), i)
    kind = i % 10
    if kind == 0:
        return [rng.bytes(int(rng.integers(0, 64))) for _ in range(int(rng.integers(1, 4)))]
    if kind == 1:
        h = bytes(good[0])
        return [h[: int(rng.integers(0, len(h)))]]
    if kind == 2:
        return encode(Message("refine.insert_lobe", i, {"session": "s"}, {"indices": np.zeros(4, np.float32)}))
    if kind == 3:
        return [msgpack.packb({"v": PROTOCOL_VERSION, "id": i, "type": "refine.insert_lobe", "body": {},
                               "arrays": [["indices", "<i8", [1 << 39, 1 << 20]]]}), b"x" * 8]
    if kind == 4:
        return encode(Message(f"op.{int(rng.integers(0, 10**6))}", i, {}))
    if kind == 5:
        return [msgpack.packb({"v": int(rng.integers(2, 100)), "id": i, "type": "ping"})]
    if kind == 6:
        return [msgpack.packb({"v": PROTOCOL_VERSION, "id": i, "type": "ping", "arrays": [["a", "|O", [1]]]}), b"\x00"]
    if kind == 7:
        return encode(Message("session.load", i, {"assembly": {"placements": [{"instance": [], "T_world_example": 3}]}}))
    if kind == 8:
        return [msgpack.packb([1, 2, 3])] + [b"" for _ in range(int(rng.integers(0, 3)))]
    return encode(Message("assembly.transform", i, {"session": "s", "instance": "x", "scale": "big"},
                          {"T_world_example": np.eye(4)[:3]}))


def test_ten_thousand_malformed_messages_leave_the_server_serving(served):
    rng = np.random.default_rng(0)
    s = raw_socket(served)
    codes: dict[str, int] = {}
    for batch in range(20):
        for j in range(500):
            s.send_multipart(malformed(rng, batch * 500 + j + 1))
        for _ in range(500):
            _, reply = P.parse(s.recv_multipart())
            assert isinstance(reply, P.Error)
            codes[reply.code] = codes.get(reply.code, 0) + 1
    s.close(0)
    assert sum(codes.values()) == 10_000
    assert set(codes) == {"protocol", "unknown_type", "version"}
    with Remote(served.endpoint, timeout=5) as r:
        sid = r.new_session().session
        assert r.add_example(sid, "ex-1").revision == 1
        assert r.ping() < 1.0


def test_wrong_protocol_version_names_both_versions(served):
    s = raw_socket(served)
    s.send_multipart([msgpack.packb({"v": 7, "id": 9, "type": "hello", "body": {}})])
    rid, reply = P.parse(s.recv_multipart())
    s.close(0)
    assert rid == 9 and reply.code == "version"
    assert "client speaks protocol 7" in reply.message and f"server speaks {PROTOCOL_VERSION}" in reply.message


def edit_loop(endpoint: str, k: int, seconds: float, out: dict) -> None:
    with Remote(endpoint, timeout=20) as r:
        sid = r.new_session(f"client {k}").session
        r.add_example(sid, f"ex-{k % 4}", instance=f"c{k}")
        n, end = 0, time.monotonic() + seconds
        while time.monotonic() < end:
            n += 1
            r.transform_example(sid, f"c{k}", make_transform(t=[k, n, 0]), scale=1.0 + n * 1e-3)
        out[k] = (sid, n)


def run_clients(served: Server, seconds: float) -> None:
    out: dict[int, tuple[str, int]] = {}
    threads = [threading.Thread(target=edit_loop, args=(served.endpoint, k, seconds, out)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(seconds + 60)
    assert sorted(out) == list(range(8))
    with Remote(served.endpoint) as r:
        for k, (sid, n) in out.items():
            a = r.assembly(sid)
            assert a.revision == n + 1
            (p,) = a.assembly.placements
            assert p.instance == f"c{k}" and p.example_id == f"ex-{k % 4}"
            assert np.allclose(p.T_world_example[:3, 3], [k, n, 0]) and p.scale == pytest.approx(1 + n * 1e-3)
    assert len({sid for sid, _ in out.values()}) == 8


def test_eight_clients_edit_concurrently_and_lose_nothing(served):
    run_clients(served, 8.0)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_eight_clients_edit_for_a_minute(served):
    run_clients(served, 60.0)


def test_jobs_stream_progress_and_never_block_edits(served):
    result: dict = {}

    def long_job():
        with Remote(served.endpoint, timeout=10) as r:
            sid = r.new_session().session
            events = []
            f = r.call(P.ExportMesh(session=sid, seed=30), progress=lambda *a: events.append(a))
            result.update(events=events, reply=f)

    t = threading.Thread(target=long_job)
    t.start()
    with Remote(served.endpoint) as r:
        sid = r.new_session().session
        r.add_example(sid, "ex-0")
        time.sleep(1.0)  # the worker is up and running its 3 s job now
        lat = []
        for i in range(50):
            t0 = time.perf_counter()
            r.transform_example(sid, "ex-0#1", make_transform(t=[i, 0, 0]))
            lat.append(time.perf_counter() - t0)
    t.join(30)
    assert max(lat) < 0.5 and sorted(lat)[25] < 0.05
    assert result["reply"].stats == {"steps": 20} and list(result["reply"].data) == [0, 1, 2, 3]
    assert len(result["events"]) >= 10 and result["events"][-1][:2] == (20.0, 20.0)


def test_a_progress_callback_returning_false_cancels_the_job(served):
    with Remote(served.endpoint, timeout=10) as r:
        sid = r.new_session().session
        t0 = time.monotonic()
        with pytest.raises(RemoteError) as e:
            r.call(P.ExportMesh(session=sid, seed=100), progress=lambda done, total, msg: done < 3)
        assert e.value.code == "cancelled" and time.monotonic() - t0 < 8
        assert r.ping() < 1.0


def test_a_retried_request_is_applied_once(served):
    with Remote(served.endpoint) as r:
        sid = r.new_session().session
        r.add_example(sid, "ex-2")
    s = raw_socket(served)
    frames = P.to_frames(P.TransformExample(session=sid, instance="ex-2#1", T_world_example=np.eye(4)), 777)
    replies = []
    for _ in range(3):
        s.send_multipart(frames)
        replies.append(P.parse(s.recv_multipart())[1])
    s.close(0)
    assert [x.revision for x in replies] == [2, 2, 2]


def test_lazy_pirate_reconnects_when_the_server_comes_back(tmp_path):
    probe = zmq.Context.instance().socket(zmq.ROUTER)
    port = probe.bind_to_random_port("tcp://127.0.0.1")
    probe.close(0)
    endpoint = f"tcp://127.0.0.1:{port}"
    r = Remote(endpoint, timeout=0.3, retries=1, handshake=False)
    t0 = time.monotonic()
    with pytest.raises(RemoteError) as e:
        r.ping()
    assert e.value.code == "timeout" and time.monotonic() - t0 < 2.0
    ctx = Context(Sessions(tmp_path / "state"))
    server = Server(Dispatcher(ctx), endpoint, jobs=JobRunner(1))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        r.timeout, r.retries = 2.0, 3
        assert r.ping() < 2.0
        assert isinstance(r.call(P.Hello()), P.Welcome)
    finally:
        r.close()
        server.stop_event.set()
        thread.join(10)


def test_a_dying_or_refusing_worker_is_an_error_reply(served):
    with Remote(served.endpoint, timeout=20) as r:
        with pytest.raises(RemoteError) as e:
            r.call(P.Grow(session="s"))
        assert e.value.code == "internal" and "exit code 3" in str(e.value)
        with pytest.raises(RemoteError) as e:
            r.call(P.ExportModules(session="s"))
        assert e.value.code == "bad_input" and str(e.value) == "this scan has no tree in it"
        assert r.ping() < 1.0


def test_a_full_job_queue_answers_busy(tmp_path):
    ctx = Context(Sessions(tmp_path / "state"))
    handlers = load_handlers()
    handlers[P.ExportMesh] = slow_export
    server = Server(Dispatcher(ctx, handlers), "tcp://127.0.0.1:0", jobs=JobRunner(1, max_queued=1))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        s = raw_socket(server)
        s.setsockopt(zmq.RCVTIMEO, 20000)
        for i in range(3):
            s.send_multipart(P.to_frames(P.ExportMesh(session="s", seed=1), 100 + i))
        got, busy = [], []
        while len(got) < 2 or not busy:  # the queued one runs after the first: both finish, with progress between
            rid, msg = P.parse(s.recv_multipart())
            if isinstance(msg, P.Progress):  # the first job's may come before the third's refusal (CI, loaded)
                continue
            if isinstance(msg, P.ExportFile):
                got.append(rid)
            else:
                busy.append((rid, msg.code))
        assert busy == [(102, "busy")]  # the third cannot even queue
        assert got == [100, 101]
        s.close(0)
    finally:
        server.stop_event.set()
        thread.join(10)
