"""The client API with CurveZMQ keys, the keys command and the loopback-only rule of ``serve``."""

from __future__ import annotations

import threading

import pytest

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.remote import Remote, RemoteError
from arboretum_server.service.cli import check_bind, curve_keys
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher
from arboretum_server.service.jobs import JobRunner
from arboretum_server.service.sessions import Sessions
from arboretum_server.service.socket import Server

pytestmark = pytest.mark.timeout(60)


def test_keys_generate_writes_both_pairs_and_refuses_to_overwrite(tmp_path, capsys):
    assert main(["keys", "generate", str(tmp_path / "k"), "--json"]) == 0
    names = sorted(p.relative_to(tmp_path / "k").as_posix() for p in (tmp_path / "k").rglob("*") if p.is_file())
    assert names == ["client.key_secret", "clients/client.key", "server.key", "server.key_secret"]
    assert (tmp_path / "k" / "server.key_secret").stat().st_mode & 0o077 == 0
    assert main(["keys", "generate", str(tmp_path / "k")]) == 2
    assert "already holds keys" in capsys.readouterr().err


def test_curve_server_accepts_key_holders_only(tmp_path):
    main(["keys", "generate", str(tmp_path / "k")])
    main(["keys", "generate", str(tmp_path / "other")])
    keys, auth = curve_keys(str(tmp_path / "k"))
    ctx = Context(Sessions(tmp_path / "state"))
    server = Server(Dispatcher(ctx), "tcp://127.0.0.1:0", jobs=JobRunner(1), curve_secret=keys)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        with Remote(server.endpoint, curve=tmp_path / "k", timeout=5) as r:
            assert r.welcome is not None and r.ping() < 1.0
        with pytest.raises(RemoteError) as e:
            Remote(server.endpoint, curve=tmp_path / "other", timeout=0.5, retries=0)
        assert e.value.code == "timeout"
        with pytest.raises(RemoteError):
            Remote(server.endpoint, timeout=0.5, retries=0)  # plain text is refused
    finally:
        server.stop_event.set()
        thread.join(10)
        auth.stop()


@pytest.mark.parametrize("bind", ["tcp://0.0.0.0:5555", "tcp://192.168.1.4:5555", "tcp://*:5555"])
def test_non_loopback_binds_need_curve_or_insecure(bind):
    with pytest.raises(InputError, match="--curve KEYDIR"):
        check_bind(bind, None, False)
    check_bind(bind, "keys", False)
    check_bind(bind, None, True)
    check_bind("tcp://127.0.0.1:5555", None, False)


def test_remote_without_server_times_out_quickly():
    import time

    t0 = time.monotonic()
    with pytest.raises(RemoteError) as e:
        Remote("tcp://127.0.0.1:9", timeout=0.2, retries=2)
    assert e.value.code == "timeout" and "no answer" in str(e.value)
    assert time.monotonic() - t0 < 2.0
