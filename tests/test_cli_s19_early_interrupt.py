"""A Ctrl-C while ``arboretum`` registers its commands (before the command line is parsed; numpy and the
commands' modules load then) ends with the usual one line and exit 130, not a 28-44-line traceback
(session 19, helper-134's measurement)."""

from __future__ import annotations

import json

import pytest

from arboretum_library import cli


@pytest.fixture
def interrupted_registration(monkeypatch):
    def register(sub, group, only=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "register_extensions", register)


def test_ctrl_c_while_registering_is_one_line(interrupted_registration, capsys):
    assert cli.main(["library", "build", "scans", "--library", "L"]) == 130
    out, err = capsys.readouterr()
    assert (out, err) == ("", "arboretum library: interrupted\n")


def test_ctrl_c_while_registering_gives_json_when_asked(interrupted_registration, capsys):
    assert cli.main(["decompose", "tree.xyz", "--json"]) == 130
    out, err = capsys.readouterr()
    assert json.loads(out) == {"command": "decompose", "error": "interrupted", "exit": 130}
    assert err == "arboretum decompose: interrupted\n"


def test_ctrl_c_before_any_command_word(interrupted_registration, capsys):
    assert cli.main(["--json"]) == 130
    out, err = capsys.readouterr()
    assert json.loads(out)["command"] == "arboretum" and err == "arboretum: interrupted\n"


@pytest.mark.parametrize("json_flag", [False, True])
def test_ctrl_c_while_python_loads_the_cli(monkeypatch, capsys, json_flag):
    # the console script's first ~40 ms: a traceback through argparse's, json's and importlib.metadata's
    # imports until session 19
    import builtins

    from arboretum_library import entry

    real = builtins.__import__

    def loading(name, globals=None, locals=None, fromlist=(), level=0):
        if name in ("cli", "arboretum_library.cli") and fromlist and "main" in fromlist:
            raise KeyboardInterrupt
        return real(name, globals, locals, fromlist, level)

    monkeypatch.setattr(entry, "skip_exit_collection", lambda: None)  # not in the test process (session 31)
    monkeypatch.setattr(builtins, "__import__", loading)
    monkeypatch.setattr("sys.argv", ["arboretum", "scan", "info", "x.ply"] + ["--json"] * json_flag)
    with pytest.raises(SystemExit) as stop:
        entry.run()
    assert stop.value.code == 130
    out, err = capsys.readouterr()
    assert err == "arboretum scan: interrupted\n"
    assert (json.loads(out) if json_flag else out) == (
        {"command": "scan", "error": "interrupted", "exit": 130} if json_flag else "")
