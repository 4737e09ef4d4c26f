"""``library build`` (session 19): a Ctrl-C or SIGTERM while the LocalCluster starts is held until the
cluster is up and then stops the build (before, SIGINT was ignored for the start and a Ctrl-C then was lost:
the build ran to its end)."""

from __future__ import annotations

import os
import signal
import sqlite3
from pathlib import Path

import pytest

from arboretum_library.assets import sample_scans
from arboretum_library.cli import main
from arboretum_server.batch.build import BuildOptions, _Cluster
from arboretum_server.batch.signals import sigint_waits, sigterm_stops

SCANS = [str(p) for p in sample_scans()[::3]]  # two of the bundled scans
ARGS = ["--workers", "1", "--points", "1500"]


@pytest.fixture
def sending(monkeypatch) -> dict:
    """Have the LocalCluster's start send this process ``sending["signum"]`` before it starts the workers:
    the signal comes while the start runs, as a Ctrl-C in the terminal does. ``sending["starts"]``: the
    signals sent, one per start; ``sending["signum"] = None`` sends none."""
    import distributed

    sending = {"signum": signal.SIGINT, "starts": []}

    class Sending(distributed.LocalCluster):
        def __init__(self, *args, **kwargs) -> None:
            if sending["signum"] is not None:
                sending["starts"].append(sending["signum"])
                os.kill(os.getpid(), sending["signum"])
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(distributed, "LocalCluster", Sending)
    return sending


def _state(lib: Path) -> tuple[int, list[str]]:
    """(catalog rows, example folders) of a library."""
    with sqlite3.connect(f"file:{lib}/catalog.sqlite?mode=ro", uri=True) as c:
        rows = c.execute("select count(*) from examples").fetchone()[0]
    return rows, sorted(os.listdir(lib / "examples"))


@pytest.mark.parametrize("signum, code, line", [(signal.SIGINT, 130, "arboretum library: interrupted"),
                                                (signal.SIGTERM, 143, "arboretum library: interrupted (SIGTERM)")])
def test_a_signal_during_the_cluster_start_stops_the_build(tmp_path, capsys, sending, signum, code, line):
    """Before, the Ctrl-C was lost (exit 0, both scans stored); SIGTERM already waited and stopped."""
    sending["signum"] = signum
    lib = tmp_path / "L"
    assert main(["library", "build", *SCANS, "--library", str(lib), *ARGS]) == code
    out, err = capsys.readouterr()
    assert sending["starts"] == [signum]  # the signal came during the start
    assert out == "" and err.strip().splitlines() == [line]
    assert not lib.exists()  # created by this build and nothing stored: removed again


def test_a_ctrl_c_during_the_start_leaves_an_existing_library_as_it_was(tmp_path, capsys, sending):
    lib = tmp_path / "L"
    sending["signum"] = None  # first a build without the signal: one scan stored
    assert main(["library", "build", SCANS[0], "--library", str(lib), *ARGS]) == 0
    before = _state(lib)
    capsys.readouterr()
    assert before[0] >= 1 and len(before[1]) == before[0]
    sending["signum"] = signal.SIGINT
    assert main(["library", "build", *SCANS, "--library", str(lib), *ARGS]) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["arboretum library: interrupted"]
    assert sending["starts"] == [signal.SIGINT] and _state(lib) == before


def test_sigint_waits_holds_a_ctrl_c_until_the_block_ends():
    handler = signal.getsignal(signal.SIGINT)
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    done = []
    with pytest.raises(KeyboardInterrupt), sigint_waits():
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)  # a second Ctrl-C: one stop
        done.append(signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []))  # not cut short
    assert done == [True]
    assert signal.getsignal(signal.SIGINT) is handler and signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask
    with sigint_waits():  # no Ctrl-C: nothing raised
        pass


def test_local_workers_start_with_sigint_blocked_and_then_ignore_it():
    """Blocked in their mask (inherited from the start's threads), so a Ctrl-C before their preload ignores
    SIGINT cannot reach them; the client's own mask and handler are as before."""
    handler = signal.getsignal(signal.SIGINT)
    with sigterm_stops(), _Cluster(BuildOptions(workers=1)) as (client, _, _):
        seen = client.run(lambda: (signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []),
                                   signal.getsignal(signal.SIGINT) == signal.SIG_IGN))
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
        assert signal.getsignal(signal.SIGINT) is handler
    assert list(seen.values()) == [(True, True)]


def _hold(conn) -> None:
    """Keep a connection open until the other side closes it (or resets it)."""
    try:
        conn.recv(1)
    except OSError:
        pass


def test_a_scheduler_address_answering_http_is_one_line(tmp_path, capsys):
    """Before, Dask read "HTTP/1.1" as a frame length and the build ended in a 53-line traceback of a
    MemoryError ("Unable to allocate 3.07 EiB"), exit 1."""
    import socket
    import threading

    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def answer() -> None:  # every connection: the probe's (``build._probe``), then Dask's
        while True:
            try:
                conn, _ = server.accept()
            except OSError:  # closed
                return
            conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
            threading.Thread(target=_hold, args=(conn,), daemon=True).start()

    threading.Thread(target=answer, daemon=True).start()
    assert _build_against(server, tmp_path, capsys) == [
        f"arboretum library: error: --scheduler tcp://127.0.0.1:{port}: what answers there is not a Dask scheduler "
        "(MemoryError)"]


def test_a_scheduler_address_that_never_answers_is_one_line(tmp_path, capsys, monkeypatch):
    """A port that accepts and never speaks: Dask's client waited for its handshake with no deadline,
    and the build hung until killed (helper-134: 10 minutes, then SIGTERM)."""
    import socket

    from arboretum_server.batch import build

    monkeypatch.setattr(build, "PROBE_SECONDS", 0.3)
    server = socket.create_server(("127.0.0.1", 0))  # the kernel accepts into its backlog; nobody speaks
    port = server.getsockname()[1]
    assert _build_against(server, tmp_path, capsys) == [
        f"arboretum library: error: --scheduler tcp://127.0.0.1:{port}: nothing answered within 0.3 s; a Dask "
        "scheduler speaks as soon as it accepts a connection"]


def _build_against(server, tmp_path, capsys) -> list[str]:
    """stderr's lines of a build given ``server``'s address as --scheduler, which must fail (exit 2)
    without making the library; the server is closed after."""
    port, lib = server.getsockname()[1], tmp_path / "L"
    try:
        assert main(["library", "build", SCANS[0], "--library", str(lib), "--scheduler", f"tcp://127.0.0.1:{port}"]) == 2
    finally:
        server.close()
    assert not lib.exists()
    return capsys.readouterr().err.strip().splitlines()
