"""Curve key pairs that do not match (review s10, finding 7): ``serve --curve`` refuses a ``server.key``
that is not the public half of ``server.key_secret``; ``keys generate`` runs started together on one new
folder share one server pair; an interrupted ``--force`` leaves the old client pair or the new one."""

from __future__ import annotations

import os
import random
import signal
import threading
from pathlib import Path

import pytest
import zmq

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.remote import load_key
from arboretum_server.service.cli import check_server_public, curve_keys
from arboretum_server.service.keys import generate

pytestmark = pytest.mark.timeout(60)


def _foreign_server_key(folder: Path) -> None:
    """Replace ``folder/server.key`` by the public half of another pair (a copy from another folder)."""
    pub, _ = zmq.curve_keypair()
    (folder / "server.key").write_text(f'metadata\ncurve\n    public-key = "{pub.decode()}"\n')


def test_curve_keys_refuse_a_server_key_of_another_pair(tmp_path):
    generate(tmp_path / "k")
    _foreign_server_key(tmp_path / "k")
    with pytest.raises(InputError) as info:
        curve_keys(str(tmp_path / "k"))
    k = tmp_path / "k"
    assert str(info.value).startswith(f"--curve {k}: {k / 'server.key'} is not the public key of "
                                      f"{k / 'server.key_secret'}, so no client given it could connect")


def test_serve_refuses_to_start_with_one_line_naming_both_files(tmp_path, capsys):
    generate(tmp_path / "k")
    _foreign_server_key(tmp_path / "k")
    capsys.readouterr()
    code = main(["serve", "--bind", "tcp://127.0.0.1:0", "--curve", str(tmp_path / "k"), "--state", str(tmp_path / "st")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "server.key is not the public key of" in err[0] and str(tmp_path / "k" / "server.key_secret") in err[0]
    assert not (tmp_path / "st").exists()


def test_a_matching_or_absent_server_key_is_taken(tmp_path):
    generate(tmp_path / "k")
    (pub, _), auth = curve_keys(str(tmp_path / "k"))
    auth.stop()
    assert pub == load_key(tmp_path / "k" / "server.key")[0]
    (tmp_path / "k" / "server.key").unlink()  # the server needs only its secret
    assert check_server_public(tmp_path / "k", pub) is None
    generate(tmp_path / "other")
    with pytest.raises(InputError, match="is not the public key of"):  # another folder's server.key
        check_server_public(tmp_path / "other", pub)


def test_runs_started_together_on_a_new_folder_share_one_server_pair(tmp_path, monkeypatch):
    real = os.replace
    rng = random.Random(7)
    delays = [rng.uniform(0, 0.004) for _ in range(1000)]

    def slow_replace(src, dst):  # widen the window between a pair's two renames (and between runs)
        if Path(dst).name.startswith("server.key"):
            threading.Event().wait(delays.pop())
        return real(src, dst)

    monkeypatch.setattr(os, "replace", slow_replace)
    errors: list[BaseException] = []
    for trial in range(25):
        folder = tmp_path / str(trial)
        barrier = threading.Barrier(3)

        def run(name: str, folder: Path = folder, barrier: threading.Barrier = barrier) -> None:
            barrier.wait()
            try:
                generate(folder, name)
            except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
                errors.append(exc)

        threads = [threading.Thread(target=run, args=(n,)) for n in ("alice", "bob", "carol")]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert errors == []
        server_pub = load_key(folder / "server.key")[0]
        assert load_key(folder / "server.key_secret", secret=True)[0] == server_pub, f"trial {trial}"
        for name in ("alice", "bob", "carol"):
            assert load_key(folder / f"{name}.key_secret", secret=True)[0] == load_key(folder / "clients" / f"{name}.key")[0]
        assert not list(folder.rglob(".*"))  # no temporary or lock file left


def test_ctrl_c_during_force_leaves_a_matching_client_pair(tmp_path, monkeypatch):
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    k = tmp_path / "k"
    generate(k)
    old = load_key(k / "clients" / "client.key")[0]
    real = os.replace

    def replace(src, dst):  # Ctrl-C right after the new secret is in place, before its public half
        real(src, dst)
        if Path(dst).name == "client.key_secret":
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        generate(k, force=True)
    secret_pub = load_key(k / "client.key_secret", secret=True)[0]
    assert secret_pub == load_key(k / "clients" / "client.key")[0] != old
    assert not list(k.rglob(".*"))
