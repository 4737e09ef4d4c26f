"""Curve key pairs that do not match (review s10, finding 7): ``serve --curve`` refuses a ``server.key``
that is not the public half of ``server.key_secret``; ``keys generate`` runs started together on one new
folder share one server pair; an interrupted ``--force`` leaves the old client pair or the new one."""

from __future__ import annotations

import errno
import fcntl
import os
import random
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest
import zmq

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.remote import Remote, load_key
from arboretum_server.service.cli import check_server_public, curve_keys
from arboretum_server.service.keys import generate
from factories import held_folder

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


# ---------------------------------------------------------------- a secret in a public-key file (review 10b)


def _secret_of(path: Path) -> str:
    return load_key(path, secret=True)[1].decode()


def test_serve_refuses_a_server_key_holding_the_server_secret_without_printing_it(tmp_path, capsys):
    k = tmp_path / "k"
    generate(k)
    shutil.copy(k / "server.key_secret", k / "server.key")  # the file handed to clients now leaks the secret
    with pytest.raises(InputError) as info:
        check_server_public(k, load_key(k / "server.key_secret", secret=True)[0])
    assert str(info.value).startswith(f"--curve {k}: {k / 'server.key'}: is a public-key file")
    assert "secret-key line" in str(info.value) and _secret_of(k / "server.key_secret") not in str(info.value)
    capsys.readouterr()
    code = main(["serve", "--bind", "tcp://127.0.0.1:0", "--curve", str(k), "--state", str(tmp_path / "st")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert str(k / "server.key") in err[0] and _secret_of(k / "server.key_secret") not in err[0]
    assert not (tmp_path / "st").exists()


def test_serve_refuses_a_client_key_holding_that_client_secret(tmp_path):
    k = tmp_path / "k"
    generate(k)
    generate(k, "bob")
    shutil.copy(k / "bob.key_secret", k / "clients" / "bob.key")
    with pytest.raises(InputError) as info:
        curve_keys(str(k))
    message = str(info.value)
    assert f"{k / 'clients' / 'bob.key'}: is a public-key file" in message and "secret-key line" in message
    assert _secret_of(k / "bob.key_secret") not in message and "\n" not in message


def test_remote_refuses_a_server_key_holding_a_secret(tmp_path):
    k = tmp_path / "k"
    generate(k)
    shutil.copy(k / "server.key_secret", k / "server.key")
    with pytest.raises(InputError) as info:
        Remote("tcp://127.0.0.1:9", curve=k, handshake=False)
    assert str(info.value).startswith(f"{k / 'server.key'}: is a public-key file")
    assert _secret_of(k / "server.key_secret") not in str(info.value)


def test_public_key_files_still_load_and_secrets_load_only_as_secrets(tmp_path):
    k = tmp_path / "k"
    generate(k)
    pub, sec = load_key(k / "client.key_secret", secret=True)
    assert load_key(k / "clients" / "client.key") == (pub, None) and sec is not None
    with pytest.raises(InputError, match="is a public-key file"):
        load_key(k / "client.key_secret")


# ---------------------------------------------------------------- the folder lock: wait, tell, give up (review 10b)


@pytest.fixture
def held(tmp_path):
    """The key folder ``tmp_path / 'k'``, with its ``flock`` held here on another descriptor (as another
    run would); yields a function releasing it."""
    with held_folder(tmp_path / "k") as release:
        yield release


def test_a_busy_folder_is_told_once_then_given_up_with_one_line(tmp_path, held):
    told: list[str] = []
    start = time.monotonic()
    with pytest.raises(InputError) as info:
        generate(tmp_path / "k", timeout=0.3, on_wait=told.append)
    assert 0.3 <= time.monotonic() - start < 5
    assert told == [f"waiting for another 'arboretum keys generate' on {tmp_path / 'k'} ... (Ctrl-C to stop)"]
    assert str(info.value) == (f"DIR {tmp_path / 'k'}: another 'arboretum keys generate' held it for 0.3 s; "
                               "try again when it is done")
    assert not (tmp_path / "k" / "server.key").exists()


def test_a_run_waiting_for_the_lock_goes_on_when_it_is_released(tmp_path, held):
    told: list[str] = []
    timer = threading.Timer(0.3, held)
    timer.start()
    paths = generate(tmp_path / "k", "alice", timeout=20, on_wait=told.append)
    timer.join()
    assert len(told) == 1 and paths["server_key"] == "created"
    assert load_key(tmp_path / "k" / "alice.key_secret", secret=True)[0] == load_key(Path(paths["client_public"]))[0]


def test_the_cli_says_it_waits_on_stderr_then_gives_up(tmp_path, held, capsys, monkeypatch):
    from arboretum_server.service import keys

    monkeypatch.setattr(keys, "LOCK_TIMEOUT_S", 0.2)
    code = main(["keys", "generate", str(tmp_path / "k"), "--client", "a"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 2, err
    assert err[0].startswith("waiting for another 'arboretum keys generate' on ")
    assert "held it for 0.2 s" in err[1]


def test_a_folder_that_cannot_be_locked_is_one_input_error(tmp_path, monkeypatch):
    def no_flock(fd, op):  # what flock on a folder descriptor gives on some network filesystems
        raise OSError(errno.EBADF, os.strerror(errno.EBADF))

    monkeypatch.setattr(fcntl, "flock", no_flock)
    with pytest.raises(InputError) as info:
        generate(tmp_path / "k")
    assert str(info.value).startswith(f"DIR {tmp_path / 'k'}: cannot be locked (Bad file descriptor)")
    assert not (tmp_path / "k" / "server.key").exists()
