"""The command's cold start (session 31, issue 4's "200,000 points under 3 s end to end"): ``arboretum CMD``
registers CMD alone, a LAS file is read without ``requests`` (laspy's HTTP reader), and the command-line
process ends without the garbage collector's passes over the heap (``entry.skip_exit_collection``). Each is
checked in a new process, on ``sys.modules`` and ``gc``, never on time."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import entry_points

import numpy as np
import pytest

from arboretum_library.cli import GROUP, build_parser

OTHER_COMMANDS = ("arboretum_library.commands.scan", "arboretum_library.commands.library",
                  "arboretum_library.commands.demo", "arboretum_server.synth.cli", "arboretum_server.grow.cli",
                  "arboretum_server.service.cli", "arboretum_server.assembly.cli", "arboretum_server.photos.cli",
                  "arboretum_server.modules.cli", "arboretum_client.app_cli", "arboretum_client.render_cli")
"""Modules that only register other commands than ``decompose``."""


def _python(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "COLUMNS": "100"})


def _choices(parser) -> dict:
    return next(a.choices for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")


def test_decompose_registers_no_other_command():
    code = ("import sys\nfrom arboretum_library.cli import main\ncode = main(['decompose', 'no-such-scan.xyz'])\n"
            f"print(code, sorted(m for m in {OTHER_COMMANDS!r} if m in sys.modules))")
    run = _python(code)
    assert run.stdout.split(maxsplit=1) == ["2", "[]\n"], run.stderr
    assert "no-such-scan.xyz" in run.stderr  # the command ran, and failed on the missing file with one line


def _helps(parser, path: str = "arboretum") -> dict[str, str]:
    """Every (sub)parser's help under ``parser``, by its command path."""
    out = {path: parser.format_help()}
    for action in parser._actions:
        if action.__class__.__name__ == "_SubParsersAction":
            for name, sub in action.choices.items():
                out.update(_helps(sub, f"{path} {name}"))
    return out


@pytest.mark.parametrize("command", sorted({ep.name for ep in entry_points(group=GROUP)}))
def test_one_command_parses_and_helps_as_among_all(command, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    alone, every = build_parser(command), build_parser()
    assert list(_choices(alone)) == [command]
    assert len(_choices(every)) == len({ep.name for ep in entry_points(group=GROUP)}) > 1
    mine = {k: v for k, v in _helps(every).items() if k.startswith(f"arboretum {command}")}
    assert {k: v for k, v in _helps(alone).items() if k != "arboretum"} == mine
    assert alone.format_usage() == every.format_usage()  # "COMMAND": the usage names no command


def test_a_word_that_is_no_command_registers_them_all(monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    for word in (None, "no-such-command", "--version"):
        assert list(_choices(build_parser(word))) == list(_choices(build_parser()))


def test_reading_a_las_file_leaves_requests_out(tmp_path):
    import laspy

    pts = np.random.default_rng(0).uniform(0, 2, (500, 3))
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales, header.offsets = np.full(3, 1e-4), pts.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(tmp_path / "t.las"))
    code = ("import sys, importlib.util\nfrom arboretum_library.pointio import read_points\n"
            "c = read_points(sys.argv[1])\n"
            "print(len(c.points), round(float(c.points.sum()), 3), sorted(m for m in ('requests', 'urllib3') "
            "if m in sys.modules), [m for m, v in sys.modules.items() if v is None])\n"
            "if importlib.util.find_spec('requests'):\n    import requests\n    print(requests.__name__)")
    run = _python(code, str(tmp_path / "t.las"))
    lines = run.stdout.splitlines()
    expected = np.asarray(laspy.read(str(tmp_path / "t.las")).xyz, dtype=np.float64)
    assert lines[0] == f"500 {round(float(expected.sum()), 3)} [] []", run.stderr
    assert lines[1:] in ([], ["requests"])  # imported for real afterwards when installed


def test_a_laspy_that_needs_a_kept_out_module_is_imported_with_it():
    # laspy imports laspy.errors unconditionally: kept out, its import fails, and laspy is imported again with it
    code = ("import sys\nfrom arboretum_library import pointio_formats as f\n"
            "f.LASPY_UNUSED = ('requests', 'laspy.errors')\nlaspy = f.import_laspy()\n"
            "print(callable(laspy.read), 'laspy.errors' in sys.modules, [m for m, v in sys.modules.items() if v is None])")
    run = _python(code)
    assert run.stdout.split("\n")[0] == "True True []", run.stderr


_FROZEN_AT_EXIT = ("import atexit, gc, sys\n"
                   "atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0, flush=True))\n"
                   "sys.argv = ['arboretum', '--version']\n")


@pytest.mark.parametrize("start", [
    "from arboretum_library.entry import run\nrun()",  # the console script
    "import runpy\nrunpy.run_module('arboretum_library.cli', run_name='__main__')",  # python -m
])
def test_the_command_process_ends_without_collecting(start):
    run = _python(_FROZEN_AT_EXIT + start)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split("\n")[0].startswith("arboretum ")  # printed and flushed all the same
    assert "frozen True" in run.stdout.splitlines()


def test_importing_the_cli_collects_as_usual():
    run = _python("import atexit, gc\natexit.register(lambda: print(gc.get_freeze_count()))\n"
                  "from arboretum_library import cli, entry\ncli.main(['--version'])")
    assert run.stdout.splitlines()[-1] == "0", run.stderr


def test_the_command_process_prints_all_of_a_long_output():
    # a help of 1,900+ characters through a pipe, then the exit without the collection: all of it arrives
    run = _python("import runpy, sys\nsys.argv = ['arboretum', 'decompose', '--help']\n"
                  "runpy.run_module('arboretum_library.cli', run_name='__main__')")
    direct = _python("from arboretum_library.cli import main\ntry:\n    main(['decompose', '--help'])\n"
                     "except SystemExit:\n    pass")
    assert run.returncode == 0 and run.stdout == direct.stdout and len(run.stdout) > 1500
