"""Under ``--json`` a failing command prints one JSON object on stdout as well as its line on stderr
(helper-126's hunt, session 17: ``decompose --json`` printed nothing on stdout on an error, so a script
reading stdout as JSON broke on the very runs it needed to report)."""

from __future__ import annotations

import json

import pytest

from arboretum_library.cli import main
from arboretum_library.errors import InputError


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_a_missing_scan_gives_json_on_stdout_and_the_line_on_stderr(tmp_path, capsys):
    missing = tmp_path / "nope.xyz"
    code, out, err = _run(["decompose", str(missing), "--library", str(tmp_path / "lib"), "--json"], capsys)
    data = json.loads(out)
    assert code == 2 and data["exit"] == 2 and data["command"] == "decompose"
    assert "nope.xyz" in data["error"] and "no such file" in data["error"]
    assert err.strip() == f"arboretum decompose: error: {data['error']}"
    assert not (tmp_path / "lib").exists()


def test_without_json_stdout_stays_empty(tmp_path, capsys):
    code, out, err = _run(["decompose", str(tmp_path / "nope.xyz"), "--library", str(tmp_path / "lib")], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1


def test_a_usage_error_gives_json_too(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["decompose", "--main", "many", "--json"])
    out, err = capsys.readouterr()
    data = json.loads(out)
    assert stop.value.code == 2 and data["exit"] == 2 and data["command"] == "decompose"
    assert "--main" in data["error"] and "invalid" in data["error"] and "--main" in err


def test_a_library_action_names_itself(tmp_path, capsys):
    code, out, _ = _run(["library", "list", str(tmp_path / "absent"), "--json"], capsys)
    data = json.loads(out)
    assert code == 2 and data["command"] == "library" and "absent" in data["error"]


@pytest.mark.parametrize("raised, code, error", [(KeyboardInterrupt, 130, "interrupted"),
                                                 ("terminated", 143, "interrupted (SIGTERM)"),
                                                 (InputError("x.xyz: 3 usable points"), 2, "x.xyz: 3 usable points")])
def test_interruptions_and_mistakes_inside_the_run(monkeypatch, tmp_path, capsys, raised, code, error):
    from arboretum_server.batch.signals import Terminated
    from arboretum_server.decompose import cli as dcli

    exc = Terminated() if raised == "terminated" else raised

    def stop(args):
        raise exc

    monkeypatch.setattr(dcli, "_run", stop)
    got, out, err = _run(["decompose", str(tmp_path / "x.xyz"), "--json"], capsys)
    assert got == code and json.loads(out) == {"command": "decompose", "error": error, "exit": code}
    assert err.strip().endswith(error)


def test_a_build_stopped_by_sigterm_says_so_in_json(monkeypatch, tmp_path, capsys):
    from arboretum_server.batch import cli as bcli
    from arboretum_server.batch.signals import Terminated

    def stop(args, folder):
        raise Terminated()

    monkeypatch.setattr(bcli, "_build", stop)
    scan = tmp_path / "a.xyz"
    scan.write_text("0 0 0\n0 0 1\n")
    got, out, err = _run(["library", "build", str(scan), "--library", str(tmp_path / "L"), "--json"], capsys)
    assert got == 143 and json.loads(out) == {"command": "library", "error": "interrupted (SIGTERM)", "exit": 143}
    assert err.strip() == "arboretum library: interrupted (SIGTERM)"
