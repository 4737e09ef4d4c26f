"""The arboretum command: subcommands, errors as one line, and the generated reference."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from arboretum_library import __version__
from arboretum_library.cli import main
from arboretum_library.cli_reference import cli_reference

DOCS = Path(__file__).resolve().parents[1] / "docs" / "cli.md"
EXPECTED = {"decompose", "demo", "grow", "library", "render", "scan", "synth"}


def test_help_lists_every_subcommand(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for name in EXPECTED:
        assert f"    {name}" in out


def test_version(capsys):
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"arboretum {__version__}"


def test_help_does_not_import_heavy_packages():
    code = (
        "import sys; from arboretum_library.cli import build_parser; build_parser(); "
        "print(sorted(m for m in ('open3d','sklearn','scipy','moderngl','glfw','pycolmap','dask','pxr') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_cli_reference_is_up_to_date():
    assert DOCS.read_text() == cli_reference(), "run: python -m arboretum_library.cli_reference > docs/cli.md"
