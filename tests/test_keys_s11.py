"""Key pairs left mismatched by a kill (session 11): a ``keys generate --force`` killed (SIGKILL, power
cut) between its two renames is finished by the next run, and until then ``serve --curve``,
``keys generate`` and ``Remote(curve=...)`` name the two files that disagree instead of a silent timeout;
``keys generate --wait SECONDS`` sets the wait for another run's lock."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
import zmq

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.remote import Remote, client_keys, load_key, same_pair
from arboretum_server.service.cli import check_client_pairs, curve_keys
from arboretum_server.service.keys import generate
from factories import held_folder

pytestmark = pytest.mark.timeout(60)

KILLER = textwrap.dedent("""
    import os, signal, sys
    import zmq, arboretum_library.atomic, arboretum_library.codec, arboretum_library.recovery
    import arboretum_library.remote
    from arboretum_server.service.keys import generate

    folder, client, kill_at = sys.argv[1], sys.argv[2], int(sys.argv[3])
    calls = [0]

    def hooked(real):
        def call(*args, **kwargs):
            if calls[0] == kill_at:
                os.kill(os.getpid(), signal.SIGKILL)
            calls[0] += 1
            return real(*args, **kwargs)
        return call

    for name in ("open", "fchmod", "fsync", "replace"):
        setattr(os, name, hooked(getattr(os, name)))
    generate(folder, client, force=True)
    print(calls[0])
""")
"""A ``generate(DIR, CLIENT, force=True)`` SIGKILLed just before its ``kill_at``-th file system call
(open, fchmod, fsync, rename); without a kill it prints how many calls it made."""


def _killed_force(folder: Path, client: str, kill_at: int) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", KILLER, str(folder), client, str(kill_at)],
                          capture_output=True, text=True, timeout=30)


def _public(path: Path) -> bytes:
    return load_key(path, secret=path.name.endswith(".key_secret"))[0]


def _serve(folder: Path, tmp_path: Path, capsys) -> tuple[int, list[str]]:
    capsys.readouterr()
    rc = main(["serve", "--bind", "tcp://127.0.0.1:0", "--curve", str(folder), "--state", str(tmp_path / "st")])
    return rc, capsys.readouterr().err.strip().splitlines()


def _kill_secret_only(folder: Path, client: str) -> None:
    """What a kill between the two renames leaves: a new secret for ``client``, its old accepted key."""
    other = folder.parent / f"other-{client}"
    generate(other, client)
    os.replace(other / f"{client}.key_secret", folder / f"{client}.key_secret")


# ---------------------------------------------------------------- kills: whole or named, then finished


def test_every_kill_point_of_a_force_run_is_whole_or_named_and_the_next_run_finishes_it(tmp_path):
    base = tmp_path / "base"
    generate(base)
    generate(base, "alice")
    old = _public(base / "clients" / "alice.key")
    shutil.copytree(base, tmp_path / "count")
    calls = int(_killed_force(tmp_path / "count", "alice", -1).stdout)
    assert calls >= 7  # the lock, two temp files (open, fchmod, ...), two renames, ...
    outcomes = []
    for kill_at in range(calls):
        k = tmp_path / str(kill_at)
        shutil.copytree(base, k)
        assert _killed_force(k, "alice", kill_at).returncode == -9
        secret, accepted = k / "alice.key_secret", k / "clients" / "alice.key"
        whole = same_pair(secret, accepted)
        if whole:
            curve_keys(str(k))[1].stop()
            assert client_keys(k, "alice")[1] == _public(accepted)
        else:
            with pytest.raises(InputError, match=f"{secret} is not the secret of {accepted}"):
                curve_keys(str(k))
            with pytest.raises(InputError, match=f"{secret} and {accepted} are not one key pair"):
                client_keys(k, "alice")
        paths = generate(k, "bob")  # a later run, for another client, finishes the killed one
        assert same_pair(secret, accepted) and same_pair(k / "bob.key_secret", k / "clients" / "bob.key")
        assert not list(k.rglob(".*")), kill_at  # no leftover
        curve_keys(str(k))[1].stop()
        outcomes.append(("whole" if whole else "finished" if "recovered" in paths else "?",
                         "old" if _public(accepted) == old else "new"))
    assert ("finished", "new") in outcomes and ("whole", "old") in outcomes and outcomes[-1] == ("whole", "new")
    assert {o for o, _ in outcomes} <= {"whole", "finished"}


def test_a_first_run_killed_between_the_server_renames_is_finished(tmp_path):
    k = tmp_path / "k"
    k.mkdir()
    (k / "clients").mkdir()
    pub, sec = (x.decode() for x in zmq.curve_keypair())
    (k / ".server.key.new").write_text(f'metadata\ncurve\n    public-key = "{pub}"\n')
    (k / "server.key_secret").write_text(f'metadata\ncurve\n    public-key = "{pub}"\n    secret-key = "{sec}"\n')
    paths = generate(k)
    assert paths["server_key"] == "kept" and paths["recovered"] == str(k / "server.key")
    assert _public(k / "server.key") == pub.encode() and not list(k.rglob(".*"))


def test_a_run_killed_before_its_renames_leaves_the_old_pair_and_its_leftovers_go(tmp_path):
    k = tmp_path / "k"
    generate(k)
    old = _public(k / "clients" / "client.key")
    (k / "clients" / ".client.key.new").write_text("metadata\ncurve\n    public-key = \"trunc")  # cut short
    (k / ".client.key_secret.new").write_text("")
    with pytest.raises(InputError, match="already holds keys for the client 'client'"):
        generate(k)
    assert _public(k / "clients" / "client.key") == old == _public(k / "client.key_secret")
    assert not list(k.rglob(".*"))


def test_a_killed_first_run_for_a_client_is_finished_without_force(tmp_path):
    k = tmp_path / "k"
    generate(k)
    pub, sec = (x.decode() for x in zmq.curve_keypair())
    (k / "clients" / ".carol.key.new").write_text(f'metadata\ncurve\n    public-key = "{pub}"\n')
    (k / "carol.key_secret").write_text(f'metadata\ncurve\n    public-key = "{pub}"\n    secret-key = "{sec}"\n')
    paths = generate(k, "carol")  # the pair the killed run made is kept: it is whole now
    assert paths["recovered"] == str(k / "clients" / "carol.key")
    assert _public(k / "clients" / "carol.key") == _public(k / "carol.key_secret") == pub.encode()


# ---------------------------------------------------------------- serve --curve names the pair


def test_serve_refuses_a_mismatched_client_pair_with_one_line_naming_both_files(tmp_path, capsys):
    k = tmp_path / "k"
    generate(k)
    generate(k, "alice")
    _kill_secret_only(k, "alice")
    rc, err = _serve(k, tmp_path, capsys)
    assert rc == 2 and len(err) == 1, err
    assert f"{k / 'alice.key_secret'} is not the secret of {k / 'clients' / 'alice.key'}" in err[0]
    assert f"'arboretum keys generate {k} --client alice --force'" in err[0] and "client.key_secret" not in err[0]
    assert not (tmp_path / "st").exists()


def test_serve_names_every_mismatched_pair_and_skips_secrets_it_cannot_check(tmp_path):
    k = tmp_path / "k"
    generate(k)
    for name in ("alice", "bob", "gone", "revoked"):
        generate(k, name)
    _kill_secret_only(k, "alice")
    _kill_secret_only(k, "bob")
    (k / "gone.key_secret").unlink()  # given away: not checkable
    _kill_secret_only(k, "revoked")
    (k / "clients" / "revoked.key").unlink()  # no longer accepted: nothing to check against
    with pytest.raises(InputError) as info:
        check_client_pairs(k)
    message = str(info.value)
    assert message.count(" is not the secret of ") == 2 and "for each of alice, bob " in message
    assert "gone" not in message and "revoked" not in message and "\n" not in message
    for name in ("alice", "bob"):
        generate(k, name, force=True)
    assert check_client_pairs(k) is None


def test_serve_refuses_an_unreadable_client_secret_naming_it(tmp_path):
    k = tmp_path / "k"
    generate(k)
    (k / "client.key_secret").write_bytes(b"")
    with pytest.raises(InputError) as info:
        curve_keys(str(k))
    assert str(info.value) == (f"--curve {k}: {k / 'client.key_secret'}: is empty, not a CurveZMQ key file, so it "
                               f"cannot be checked against {k / 'clients' / 'client.key'}")


# ---------------------------------------------------------------- keys generate: report, then --force


def test_generate_names_a_mismatched_pair_and_force_mends_it(tmp_path, capsys):
    k = tmp_path / "k"
    generate(k)
    _kill_secret_only(k, "client")
    capsys.readouterr()
    assert main(["keys", "generate", str(k)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{k / 'client.key_secret'} and {k / 'clients' / 'client.key'} are not one key pair" in err[0]
    assert err[0].endswith("rerun with --force to replace both")
    assert main(["keys", "generate", str(k), "--force"]) == 0
    assert same_pair(k / "client.key_secret", k / "clients" / "client.key")
    curve_keys(str(k))[1].stop()


def test_generate_suggests_force_for_an_unreadable_secret(tmp_path):
    k = tmp_path / "k"
    generate(k)
    (k / "client.key_secret").write_text("garbage")
    with pytest.raises(InputError, match="holds no public-key line.*; rerun with --force to replace the client 'client'"):
        generate(k)
    generate(k, force=True)
    assert same_pair(k / "client.key_secret", k / "clients" / "client.key")


# ---------------------------------------------------------------- Remote(curve=DIR)


def test_remote_names_both_files_when_the_secret_disagrees_with_clients_key(tmp_path):
    k = tmp_path / "k"
    generate(k)
    generate(k, "alice")
    _kill_secret_only(k, "alice")
    start = time.monotonic()
    for curve, name in ((k, "alice"), (k / "alice.key_secret", None)):
        with pytest.raises(InputError) as info:
            Remote("tcp://127.0.0.1:9", curve=curve, curve_client=name, handshake=False)
        assert str(info.value).startswith(f"{k / 'alice.key_secret'} and {k / 'clients' / 'alice.key'} are not one "
                                          "key pair")
        assert f"'arboretum keys generate {k} --client alice --force'" in str(info.value)
    assert time.monotonic() - start < 2  # no timeout waited for
    assert client_keys(k)[1] == _public(k / "client.key_secret")  # the other client is fine
    (k / "clients" / "alice.key").unlink()  # a copy without the server's clients/: nothing to check
    assert client_keys(k, "alice")[1] == _public(k / "alice.key_secret")


# ---------------------------------------------------------------- --wait SECONDS


@pytest.fixture
def held(tmp_path):
    """``tmp_path / 'k'`` with its ``flock`` held on another descriptor (as another run would)."""
    with held_folder(tmp_path / "k") as release:
        yield release


def _keys(argv: list[str], capsys) -> tuple[int, list[str], float]:
    capsys.readouterr()
    start = time.monotonic()
    rc = main(["keys", "generate", *argv])
    return rc, capsys.readouterr().err.strip().splitlines(), time.monotonic() - start


def test_wait_zero_gives_up_at_once_without_a_waiting_line(tmp_path, held, capsys):
    rc, err, took = _keys([str(tmp_path / "k"), "--wait", "0"], capsys)
    assert rc == 2 and took < 1 and err == [
        f"arboretum keys: error: DIR {tmp_path / 'k'}: another 'arboretum keys generate' is using it (--wait 0: "
        "not waiting); try again when it is done"]


def test_wait_seconds_is_the_time_given_up_after(tmp_path, held, capsys):
    rc, err, took = _keys([str(tmp_path / "k"), "--wait", "0.4"], capsys)
    assert rc == 2 and 0.4 <= took < 3 and len(err) == 2 and "held it for 0.4 s" in err[1]


def test_wait_inf_waits_until_the_lock_is_released(tmp_path, held, capsys):
    timer = threading.Timer(0.5, held)
    timer.start()
    rc, err, took = _keys([str(tmp_path / "k"), "--wait", "inf"], capsys)
    timer.join()
    assert rc == 0 and took >= 0.5 and len(err) == 1 and err[0].startswith("waiting for another")


@pytest.mark.parametrize("value", ["-1", "nan", "-inf"])
def test_a_negative_or_nan_wait_is_one_line_before_the_lock(tmp_path, held, capsys, value):
    rc, err, took = _keys([str(tmp_path / "k"), f"--wait={value}"], capsys)
    assert rc == 2 and took < 1 and err == [f"arboretum keys: error: --wait {value}: give the seconds to wait for "
                                            "another run, 0 or more (0: do not wait)"]
    assert not (tmp_path / "k" / "server.key").exists()


def test_accepted_key_names_the_public_key_a_server_checks_a_secret_by(tmp_path):
    from arboretum_library.remote import accepted_key

    k = tmp_path / "k"
    generate(k, "alice")
    assert accepted_key(k / "alice.key_secret") == k / "clients" / "alice.key"
    assert accepted_key(k / "server.key_secret") is None  # the server's own pair
    (k / ".alice.key_secret.new").write_text("")
    assert accepted_key(k / ".alice.key_secret.new") is None  # not a *.key_secret
    (k / "clients" / "alice.key").unlink()  # revoked
    assert accepted_key(k / "alice.key_secret") is None
