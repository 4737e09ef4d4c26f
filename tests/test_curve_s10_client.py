"""CurveZMQ keys on the client side: which client secret ``Remote(curve=...)`` uses, one error line for a
bad key file, and ``arboretum client --connect ADDRESS --curve KEYDIR``."""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

import pytest

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


@pytest.fixture
def keydir(tmp_path) -> Path:
    """A key folder with the clients 'client' and 'alice'; alice is revoked on the server (p16)."""
    generate(tmp_path / "k")
    generate(tmp_path / "k", "alice")
    (tmp_path / "k" / "clients" / "alice.key").unlink()
    return tmp_path / "k"


@pytest.fixture
def curve_server(keydir, tmp_path):
    keys, auth = curve_keys(str(keydir))
    server = Server(Dispatcher(Context(Sessions(tmp_path / "state"))), "tcp://127.0.0.1:0", jobs=JobRunner(1),
                    curve_secret=keys)
    try:
        with serving(server):
            yield server
    finally:
        auth.stop()


def _public(path: Path) -> bytes:
    return remote.load_key(path, secret=path.name.endswith(".key_secret"))[0]  # a secret only as a secret


# ---------------------------------------------------------------- which secret (p16)


def test_curve_folder_uses_client_key_secret_before_other_names(keydir, curve_server):
    with Remote(curve_server.endpoint, curve=keydir, timeout=5) as r:  # 'alice' sorts first, but is revoked
        assert r.welcome is not None
    with pytest.raises(RemoteError) as e:
        Remote(curve_server.endpoint, curve=keydir, curve_client="alice", timeout=0.5, retries=0)
    assert e.value.code == "timeout"
    with pytest.raises(RemoteError):
        Remote(curve_server.endpoint, curve=keydir / "alice.key_secret", timeout=0.5, retries=0)


def test_client_keys_choose_by_name_path_or_the_only_secret(keydir, tmp_path):
    server_pub = _public(keydir / "server.key")
    alice, client = _public(keydir / "alice.key_secret"), _public(keydir / "clients" / "client.key")
    assert remote.client_keys(keydir)[:2] == (server_pub, client)
    assert remote.client_keys(keydir, "alice")[:2] == (server_pub, alice)
    assert remote.client_keys(str(keydir / "alice.key_secret"))[:2] == (server_pub, alice)
    only = tmp_path / "only"
    only.mkdir()
    for name in ("server.key", "alice.key_secret"):  # what an admin hands to alice
        shutil.copy(keydir / name, only / name)
    assert remote.client_keys(only)[:2] == (server_pub, alice)


def test_several_secrets_without_client_key_secret_are_listed(keydir):
    generate(keydir, "bob")
    (keydir / "client.key_secret").unlink()
    with pytest.raises(InputError, match=r"several client secrets \(alice, bob\) and no client.key_secret"):
        remote.client_keys(keydir)
    with pytest.raises(InputError, match=r"no carol.key_secret \(client secrets here: alice, bob\)"):
        remote.client_keys(keydir, "carol")
    assert remote.client_keys(keydir, "bob")[1] == _public(keydir / "clients" / "bob.key")


def test_bad_choices_are_input_errors(keydir, tmp_path):
    with pytest.raises(InputError, match="is the server's secret key"):
        remote.client_keys(keydir / "server.key_secret")
    with pytest.raises(InputError, match="picks a secret in a key folder"):
        remote.client_keys(keydir / "alice.key_secret", "alice")
    with pytest.raises(InputError, match="needs curve=KEYDIR"):
        Remote("tcp://127.0.0.1:9", curve_client="alice", handshake=False)
    with pytest.raises(InputError, match="no such key folder"):
        Remote("tcp://127.0.0.1:9", curve=tmp_path / "nothing", handshake=False)
    (keydir / "server.key").unlink()
    with pytest.raises(InputError, match="needs server.key .* next to client.key_secret"):
        remote.client_keys(keydir)


# ---------------------------------------------------------------- bad key files (p4)


@pytest.mark.parametrize("name, text, message", [
    ("server.key", b"junk\n", "server.key: holds no public-key line"),
    ("server.key", b"", "server.key: is empty"),
    ("client.key_secret", b"junk\n", "client.key_secret: holds no public-key line"),
    ("client.key_secret", None, "client.key_secret: holds no secret key"),  # the public file copied over it
    ("client.key_secret", b"cut", "client.key_secret: its secret key is not 40 Z85 characters"),
])
def test_a_bad_key_file_is_one_input_error_naming_it(keydir, name, text, message):
    (keydir / "alice.key_secret").unlink()  # client.key_secret is then the one choice, before and after p16
    path = keydir / name
    if text is None:
        text = (keydir / "clients" / "client.key").read_bytes()
    elif text == b"cut":
        text = path.read_bytes()[:-8]
    path.write_bytes(text)
    with pytest.raises(InputError, match=message):
        Remote("tcp://127.0.0.1:9", curve=keydir, handshake=False)


# ---------------------------------------------------------------- arboretum client --curve (p7)


def _client_parser() -> argparse.ArgumentParser:
    from arboretum_client import app_cli

    parser = argparse.ArgumentParser()
    app_cli.register(parser.add_subparsers(dest="command"))
    return parser


def test_client_takes_curve_and_its_port_factory_connects_with_it(keydir, curve_server):
    from arboretum_client.app_cli import _port_factory, check_args

    args = _client_parser().parse_args(["client", "--connect", curve_server.endpoint, "--curve", str(keydir),
                                        "--out", tempfile.gettempdir()])
    assert args.curve == str(keydir)
    assert check_args(args) == (1280, 720)
    cleanup: list = []
    session = _port_factory(args, cleanup)()
    try:
        assert session.session and session.assembly().assembly.placements == ()
        assert session.remote._curve == remote.client_keys(keydir)
    finally:
        session.remote.close()
    assert cleanup == []  # no embedded server was started


@pytest.mark.parametrize("argv, message", [
    (["--curve", "K"], "--curve KEYDIR needs --connect ADDRESS"),
    (["--offline", "--curve", "K"], "--curve KEYDIR needs --connect ADDRESS"),
    (["--connect", "tcp://127.0.0.1:9", "--curve", "K/nothing"], "--curve: K/nothing: no such key folder"),
    (["--connect", "tcp://127.0.0.1:9", "--curve", "K/server.key"], "--curve: K/server.key: holds no secret key"),
])
def test_bad_client_curve_arguments_are_one_line(keydir, tmp_path, capsys, argv, message):
    argv = [a.replace("K", str(keydir)) if a.startswith("K") else a for a in argv]
    message = message.replace("K/", f"{keydir}/")
    capsys.readouterr()
    assert main(["client", *argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("arboretum client: error: ") and message in err[0], err
    assert not (tmp_path / "out").exists()
