"""Client scripts are checked up front and startup arguments before any window (helper-52 bug 3)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile

import pytest

from arboretum_library.errors import InputError

BAD_STEPS = [
    ({"view": "back"}, "(view): unknown view 'back'"),
    ({"world": [0, 0]}, "(world): expected a world point [x, y, z]"),
    ({"mouse": [1, "a"]}, "(mouse): expected a pixel [x, y]"),
    ({"wait": "x"}, "(wait): expected seconds"),
    ({"wait": -1}, "(wait): expected seconds"),
    ({"drag": [[0, 0, 0]]}, "(drag): expected {'from'"),
    ({"drag": {"from": [0, 0, 0], "to": [1, 0, 0], "button": "thumb"}}, "(drag): unknown mouse button 'thumb'"),
    ({"hands": [{"side": "left"}]}, "(hands): hand 1: expected {'side'"),
    ({"hands": [{"side": "up", "position": [0, 0, 0]}]}, "(hands): hand 1: side must be one of left, right"),
    ({"hands": [{"side": "left", "position": [0, 0, 0], "buttons": ["fire"]}]}, "(hands): hand 1: unknown button 'fire'"),
    ({"key": "F13"}, "(key): unknown key 'F13'"),
    ({"key": "Q"}, "(key): unknown key 'Q'"),
    ({"click": "middlefinger"}, "(click): unknown mouse button 'middlefinger'"),
    ({"hold": "meta"}, "(hold): unknown modifier 'meta'"),
    ({"action": "toggle:bogus"}, "(action): toggle: expects one of show_points, show_all"),
    ({"action": "fly"}, "(action): unknown action 'fly'"),
    ({"select": []}, "(select): expected a pick name"),
    ({"stroke": [[0, 0]]}, "(stroke): expected a list of world points"),
    ({"reference": {"image": "a.png", "height": 0}}, "(reference): height must be a positive number"),
    ({"screenshot": 3}, "(screenshot): expected a PNG path"),
    ({"bogus": 1}, ": unknown step 'bogus'"),
]


@pytest.mark.parametrize(("step", "message"), BAD_STEPS)
def test_a_malformed_step_is_one_error_naming_its_number_and_key(step, message):
    from arboretum_client.script_check import check_steps

    good = [{"action": "choose:oak-0001"}, {"world": [0, 0, 0]}]
    with pytest.raises(InputError) as info:
        check_steps([*good, step])
    assert str(info.value).startswith("script step 3") and message in str(info.value), str(info.value)


def test_the_documented_scripts_and_actions_pass_the_check():
    from pathlib import Path

    from arboretum_client.script_check import check_action, check_steps
    from arboretum_client.scripts import load_script

    folder = Path(__file__).parents[1] / "docs" / "client_scripts"
    scripts = sorted(folder.glob("*.json"))
    assert len(scripts) >= 3
    for path in scripts:
        check_steps(load_script(path)["steps"])  # raises on a problem
    ok = ["undo", "grow", "density:+", "tag:dense", "toggle:show_points", "choose:pine-0002", "search:focus",
          "focus:+", "reference", "export", "save", "load"]
    assert [check_action(a) for a in ok] == [None] * len(ok)


def _client(tmp_path, *extra, steps=({"wait": 0.1},)):
    script = tmp_path / "s.json"
    script.write_text(json.dumps(list(steps)))
    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--headless", "--script", str(script),
           "--size", "320x240", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)


@pytest.mark.gl
@pytest.mark.parametrize(("step", "message"), [
    ({"key": "F13"}, "script step 2 (key): unknown key 'F13'"),
    ({"hands": [{"side": "left"}]}, "script step 2 (hands): hand 1:"),
    ({"select": ["lobe:999"]}, "script step 2 (select): nothing named 'lobe:999' in the scene"),
    ({"action": "choose:nope-0001"}, "script step 2 (action): choose:nope-0001: no such example"),
])
def test_cli_bad_steps_exit_2_with_one_line_and_no_traceback(tmp_path, step, message):
    done = _client(tmp_path, "--offline", steps=({"wait": 0.1}, step))
    assert done.returncode == 2, done.stderr[-2000:]
    assert "Traceback" not in done.stderr and message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(("args", "message"), [
    (["--library", "typo_lib"], "--library: library typo_lib does not exist"),
    (["--library", "afile"], "--library: afile is a file, not an Arboretum library folder"),
    (["--library", "empty"], "--library: library empty is not an Arboretum library"),
    (["--offline", "--library", "lib"], "--library is the embedded server's library"),
    (["--connect", "not an address"], "--connect: 'not an address' is not a server address"),
    (["--connect", "tcp://127.0.0.1:70000"], "is not a server address"),
    (["--offline", "--out", "afile"], "--out afile: is a file, not a folder"),
    (["--offline", "--size", "8x8"], "--size: 8x8 is outside 16..8192"),
])
def test_bad_startup_arguments_are_refused_before_anything_starts(tmp_path, args, message):
    (tmp_path / "afile").write_text("x")
    (tmp_path / "empty").mkdir()
    done = _client(tmp_path, *args)
    assert done.returncode == 2, (done.stdout, done.stderr[-2000:])
    assert message in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "typo_lib").exists()  # no empty library made for a mistyped path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "empty", "s.json"]


def test_endpoint_pattern_takes_real_addresses():
    import argparse

    from arboretum_client.app_cli import check_args

    base = {"size": "320x240", "headless": False, "script": None, "library": None, "offline": False,
            "out": tempfile.gettempdir()}
    for ok in ("tcp://127.0.0.1:5555", "tcp://localhost:1", "tcp://[::1]:5555", "ipc:///tmp/arb.sock"):
        assert check_args(argparse.Namespace(**base, connect=ok)) == (320, 240)
    for bad in ("127.0.0.1:5555", "tcp://host", "tcp://host:0", "http://host:80", "tcp://a b:1"):
        with pytest.raises(InputError, match="--connect"):
            check_args(argparse.Namespace(**base, connect=bad))
