"""Session 17 (helper-126's hunt): ``arboretum decompose`` stops on SIGTERM as on Ctrl-C (a library it
created is removed; before, the default handler killed it and left the library behind, empty), and a
signal that comes after the examples are committed no longer turns a finished run into a failure
(before: exit 130 with every example stored). ``arboretum_library.signals.held`` holds them."""

from __future__ import annotations

import signal
import threading

import numpy as np
import pytest

from arboretum_library.cli import main
from arboretum_library.signals import held
from arboretum_library.store import Library


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    from factories import toy_cloud

    path = tmp_path_factory.mktemp("scan") / "toy.xyz"
    np.savetxt(path, toy_cloud()[0], fmt="%.5f")
    return path


ARGS = ["--main", "3", "--lobes", "8", "--points", "2000"]


def test_held_signals_wait_for_the_end_of_the_block():
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with held(signal.SIGINT, signal.SIGTERM) as got:
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGTERM)
        reached = True  # no KeyboardInterrupt, and the process still runs
    assert reached and got == [signal.SIGINT, signal.SIGTERM]
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
    out = []

    def off_main():
        with held(signal.SIGINT) as got:
            out.append(got)

    t = threading.Thread(target=off_main)
    t.start()
    t.join()
    assert out == [[]]  # off the main thread: nothing held, no error


def test_sigterm_during_the_decomposition_removes_the_library_it_created(scan, tmp_path, monkeypatch, capsys):
    from arboretum_server.decompose import cli

    real = cli._decompose

    def terminated(*a, **k):
        signal.raise_signal(signal.SIGTERM)
        return real(*a, **k)

    monkeypatch.setattr(cli, "_decompose", terminated)
    lib = tmp_path / "new-lib"
    assert main(["decompose", str(scan), "--library", str(lib), *ARGS]) == 143
    assert not lib.exists()
    assert capsys.readouterr().err.strip().splitlines()[-1] == "arboretum decompose: interrupted (SIGTERM)"
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the command's handler is gone again


def test_a_ctrl_c_after_the_commit_keeps_the_result_and_exit_0(scan, tmp_path, monkeypatch, capsys):
    from arboretum_server.decompose import cli

    real = cli._result

    def late(*a, **k):  # the report is made after the commit
        signal.raise_signal(signal.SIGINT)
        return real(*a, **k)

    monkeypatch.setattr(cli, "_result", late)
    lib = tmp_path / "lib"
    assert main(["decompose", str(scan), "--library", str(lib), *ARGS]) == 0
    captured = capsys.readouterr()
    assert "stored 3 examples" in captured.out
    assert "Ctrl-C came after the run had finished: its result stands" in captured.err
    with Library.open(lib) as opened:
        assert len(opened.ids()) == 3
