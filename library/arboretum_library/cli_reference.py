"""Generate the command reference (docs/cli.md) from the argument parsers themselves.

    python -m arboretum_library.cli_reference > docs/cli.md

A test checks that docs/cli.md equals this output, so the reference cannot drift from the code.
"""

from __future__ import annotations

import argparse
import os

from .cli import build_parser


def _subparsers(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    out = []
    for action in parser._actions:  # argparse keeps subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            out.extend(action.choices.items())
    return out


def _walk(parser: argparse.ArgumentParser, path: str, level: int, lines: list[str]) -> None:
    lines += [f"{'#' * level} `{path}`", "", "```", parser.format_help().rstrip(), "```", ""]
    for name, sub in _subparsers(parser):
        _walk(sub, f"{path} {name}", min(level + 1, 4), lines)


def cli_reference() -> str:
    """The whole command reference as Markdown."""
    os.environ["COLUMNS"] = "100"  # stable wrapping of argparse help
    parser = build_parser()
    lines = [
        "# Command reference",
        "",
        "Generated from the code by `python -m arboretum_library.cli_reference`; do not edit by hand.",
        "",
        "A user's mistake prints one line on stderr and exits 2; Ctrl-C exits 130, SIGTERM 143 where a command",
        "handles it. Under `--json` a failing command also prints one object on stdout,",
        '`{"command": ..., "error": "the same message", "exit": 2}`, so a script reading stdout always gets JSON.',
        "",
    ]
    _walk(parser, "arboretum", 2, lines)
    return "\n".join(lines)


if __name__ == "__main__":
    print(cli_reference(), end="")
