"""CurveZMQ key files on the server side: secret modes at creation, and ``serve --curve`` refusing to
start on an unreadable key (a stray clients/README.key, an empty or mixed-up server.key_secret)."""

from __future__ import annotations

import os
import stat
import sys
import threading
from pathlib import Path

import pytest
import zmq

from arboretum_library import remote
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.remote import Remote, RemoteError
from arboretum_server.service.cli import curve_keys
from arboretum_server.service.context import Context
from arboretum_server.service.dispatch import Dispatcher
from arboretum_server.service.jobs import JobRunner
from arboretum_server.service.keys import generate
from arboretum_server.service.sessions import Sessions
from arboretum_server.service.socket import Server
from factories import serving

pytestmark = pytest.mark.timeout(60)

_WATCH: list[Path] = []
"""The folder the audit hook watches (empty: the hook does nothing)."""
_SEEN: list[tuple[str, int]] = []
_BUSY: list[bool] = []


def _audit(event: str, args: tuple) -> None:
    """Before every open/chmod/rename, record the mode of each secret file in the watched folder."""
    if not _WATCH or _BUSY or event not in ("open", "os.chmod", "os.rename", "os.replace"):
        return
    _BUSY.append(True)
    try:
        for p in _WATCH[0].rglob("*"):
            if "key_secret" in p.name:
                try:
                    _SEEN.append((p.name, stat.S_IMODE(p.stat().st_mode)))
                except FileNotFoundError:
                    pass
    finally:
        _BUSY.clear()


sys.addaudithook(_audit)  # inert unless a test fills _WATCH


@pytest.fixture
def keydir(tmp_path) -> Path:
    generate(tmp_path / "k")
    return tmp_path / "k"


def _serve(folder: Path, tmp_path: Path, capsys) -> tuple[int, list[str]]:
    capsys.readouterr()
    rc = main(["serve", "--bind", "tcp://127.0.0.1:0", "--curve", str(folder), "--state", str(tmp_path / "st")])
    return rc, capsys.readouterr().err.strip().splitlines()


# ---------------------------------------------------------------- modes (p3)


@pytest.mark.parametrize("umask", [0o022, 0o000], ids=["umask022", "umask000"])
def test_secret_files_are_never_readable_by_others(tmp_path, umask):
    old = os.umask(umask)
    _WATCH.append(tmp_path)
    try:
        generate(tmp_path / "k")
        generate(tmp_path / "k", "alice")
        generate(tmp_path / "k", "alice", force=True)
    finally:
        _WATCH.clear()
        os.umask(old)
    names = {name for name, _ in _SEEN}
    assert {"client.key_secret", "server.key_secret", "alice.key_secret"} <= names  # final files were seen
    assert {mode for _, mode in _SEEN} == {0o600}, sorted(set(_SEEN))
    _SEEN.clear()
    k = tmp_path / "k"
    modes = {p.relative_to(k).as_posix(): stat.S_IMODE(p.stat().st_mode) for p in k.rglob("*") if p.is_file()}
    assert modes == {"server.key": 0o644, "server.key_secret": 0o600, "client.key_secret": 0o600,
                     "alice.key_secret": 0o600, "clients/client.key": 0o644, "clients/alice.key": 0o644}


def test_public_keys_stay_0644_under_a_strict_umask(tmp_path):
    old = os.umask(0o077)
    try:
        generate(tmp_path / "k")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "k" / "clients" / "client.key").stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "k" / "server.key_secret").stat().st_mode) == 0o600


def test_written_pairs_match_and_force_gives_a_new_pair(keydir):
    pub, sec = remote.load_key(keydir / "client.key_secret", secret=True)
    assert zmq.curve_public(sec) == pub and len(pub) == len(sec) == 40
    assert remote.load_key(keydir / "clients" / "client.key") == (pub, None)
    server_pub, server_sec = remote.load_key(keydir / "server.key_secret", secret=True)
    assert remote.load_key(keydir / "server.key")[0] == server_pub != pub
    generate(keydir, force=True)
    assert remote.load_key(keydir / "clients" / "client.key")[0] not in (pub, server_pub)
    assert remote.load_key(keydir / "server.key_secret", secret=True) == (server_pub, server_sec)
    assert not [p.name for p in keydir.rglob(".*")]  # no temporary files left


# ---------------------------------------------------------------- clients/*.key (p2)

JUNK = {
    "README.key": b"notes\n",
    "empty.key": b"",
    "trunc.key": b'metadata\ncurve\n    public-key = "zUq(b@4ijsnFTeg/IpyJ2Ar',
    "badchar.key": b'curve\n    public-key = "' + b"~" * 40 + b'"\n',
    "overflow.key": b'curve\n    public-key = "' + b"#" * 40 + b'"\n',
    "noequals.key": b"public-key\n",
}


@pytest.mark.parametrize("name", sorted(JUNK))
def test_one_bad_client_key_refuses_to_start_naming_it(keydir, tmp_path, capsys, name):
    (keydir / "clients" / name).write_bytes(JUNK[name])
    threads = threading.active_count()
    with pytest.raises(InputError, match=f"clients/{name}: "):
        curve_keys(str(keydir))
    assert threading.active_count() == threads  # no authenticator thread left running
    rc, err = _serve(keydir, tmp_path, capsys)
    assert rc == 2 and len(err) == 1 and f"{keydir}/clients/{name}" in err[0], err
    assert not (tmp_path / "st").exists()


def test_a_folder_named_like_a_key_is_refused(keydir):
    (keydir / "clients" / "sub.key").mkdir()
    with pytest.raises(InputError, match=r"sub.key: cannot be read \(Is a directory\)"):
        curve_keys(str(keydir))


def test_an_empty_clients_folder_is_refused(keydir, tmp_path, capsys):
    (keydir / "clients" / "client.key").unlink()
    (keydir / "clients" / "notes.txt").write_text("not a key")
    with pytest.raises(InputError, match="clients/ holds no client key"):
        curve_keys(str(keydir))
    rc, err = _serve(keydir, tmp_path, capsys)
    assert rc == 2 and len(err) == 1 and "no client could connect" in err[0]


def test_other_files_and_dot_files_in_clients_are_ignored_and_keys_still_checked(keydir, tmp_path):
    (keydir / "clients" / "README.txt").write_text("the accepted clients")
    (keydir / "clients" / "._client.key").write_bytes(b"\x00\x05AppleDouble")
    keys, auth = curve_keys(str(keydir))
    server = Server(Dispatcher(Context(Sessions(tmp_path / "state"))), "tcp://127.0.0.1:0", jobs=JobRunner(1),
                    curve_secret=keys)
    try:
        with serving(server):
            with Remote(server.endpoint, curve=keydir, timeout=5) as r:
                assert r.welcome is not None
            generate(tmp_path / "other")
            with pytest.raises(RemoteError) as e:
                Remote(server.endpoint, curve=tmp_path / "other", timeout=0.5, retries=0)
            assert e.value.code == "timeout"
    finally:
        auth.stop()


# ---------------------------------------------------------------- server.key_secret (p4)


def _other_secret(folder: Path) -> bytes:
    generate(folder)
    return (folder / "server.key_secret").read_bytes()


@pytest.mark.parametrize("case, message", [
    ("empty", "is empty, not a CurveZMQ key file"),
    ("garbage", "holds no public-key line"),
    ("public_only", "holds no secret key"),
    ("truncated", "its secret key is not 40 Z85 characters"),
    ("mixed", "does not belong to its public key"),
])
def test_a_bad_server_secret_is_one_error_line(keydir, tmp_path, capsys, case, message):
    secret = keydir / "server.key_secret"
    text = secret.read_bytes()
    lines = text.splitlines()
    bad = {"empty": b"", "garbage": b"\x89PNG\r\n\x1a\n", "public_only": (keydir / "server.key").read_bytes(),
           "truncated": text[:-12],
           "mixed": b"\n".join(lines[:-1] + [_other_secret(tmp_path / "o").splitlines()[-1]])}[case]
    secret.write_bytes(bad)
    with pytest.raises(InputError, match=message):
        curve_keys(str(keydir))
    rc, err = _serve(keydir, tmp_path, capsys)
    assert rc == 2 and len(err) == 1 and f"{secret}: " in err[0] and message in err[0], err
