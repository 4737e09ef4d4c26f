"""The ``arboretum`` command: one entry point, subcommands found through entry points.

Each package registers its subcommands in pyproject under ``arboretum.commands`` as a function
``register(subparsers)`` that adds a parser and sets ``func`` (called with the parsed namespace, returns
an exit code). Registering modules import nothing heavy, so ``arboretum --help`` starts fast; the
library never imports the server or the client.

A user's mistake (``ArboretumError``) prints one line and exits 2; Ctrl-C exits 130 after the
command's own clean-up has run. With ``--json`` a failure also prints one JSON object on stdout,
``{"command", "error", "exit"}`` (``fail``), so a script reading stdout always gets JSON.
"""

from __future__ import annotations

import argparse
import errno
import json
import math
import sys
from importlib.metadata import entry_points
from typing import Any

from . import __version__
from .errors import ArboretumError

GROUP = "arboretum.commands"


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage errors also print ``fail``'s JSON when the command line asks for
    ``--json`` (subcommand parsers are made of the same class)."""

    json_errors = False

    def error(self, message: str):
        if _Parser.json_errors:
            _json_failure(self.prog.removeprefix("arboretum").strip() or "arboretum", message, 2)
        super().error(message)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``arboretum`` parser with every subcommand, or with only ``command`` when a package registers one
    of that name (``main`` passes the first word of the command line: ``arboretum decompose ...`` then
    imports no other command's module: 23 modules at session 31). Parsing a command
    line that starts with ``command`` gives the same result, help and errors either way: the top-level
    usage names no commands (``COMMAND``)."""
    parser = _Parser(
        prog="arboretum",
        description="Realistic 3D trees from real ones: scans -> HBL example libraries -> assembly -> growth -> export.",
    )
    parser.add_argument("--version", action="version", version=f"arboretum {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    register_extensions(sub, GROUP, only=command)
    return parser


def register_extensions(sub: argparse._SubParsersAction, group: str, only: str | None = None) -> None:
    """Let other packages add actions to a subcommand through the entry-point ``group``; with ``only``
    the entry points of that name alone, when there is one (else all).

    How ``arboretum library build`` (which needs Dask, a server dependency) joins the library's own
    ``library`` command without the library importing the server.
    """
    for ep in _chosen(sorted(entry_points(group=group), key=lambda e: e.name), only):
        try:
            register = ep.load()
        except ImportError as exc:
            p = sub.add_parser(ep.name, help=f"(unavailable: {exc.name} is not installed)")
            p.set_defaults(func=_unavailable(ep.name, str(exc)))
            continue
        register(sub)


def _chosen(eps: list, only: str | None) -> list:
    """The entry points of ``eps`` named ``only``; all of them when ``only`` is None or names none."""
    named = [ep for ep in eps if ep.name == only]
    return named or eps


def _first_word(words: list[str]) -> str | None:
    """The command a command line names (its first word, when that is no option), else None."""
    return words[0] if words and not words[0].startswith("-") else None


def _unavailable(name: str, why: str):
    def run(args: argparse.Namespace) -> int:
        raise ArboretumError(f"'{name}' needs a package that is not installed ({why}); run 'make install'")

    return run


def tell(message: str) -> None:
    """One line for the user on stderr now (a wait, a repair), apart from the command's output."""
    print(message, file=sys.stderr, flush=True)


def add_json_flag(parser: argparse.ArgumentParser) -> None:
    """Give a subcommand the standard ``--json`` flag."""
    parser.add_argument("--json", action="store_true", help="print a machine-readable JSON summary")


def counted(n: int, word: str) -> str:
    """``n`` and ``word``, plural unless ``n`` is 1: "1 scan", "2 scans", "0 workers"."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def emit(args: argparse.Namespace, data: Any, text: str) -> None:
    """Print ``data`` as JSON when ``--json`` was given, else the human ``text``.

    The JSON is always strict (RFC 8259), so every parser reads it: a non-finite number (NaN,
    Infinity), which JSON cannot express and Python's ``json`` would print as the bare words ``NaN`` /
    ``Infinity``, is printed as ``null``, as JavaScript's ``JSON.stringify`` does. numpy arrays and
    scalars become lists and numbers; any other object its ``str``.
    """
    if getattr(args, "json", False):
        print(json.dumps(_strict(data), indent=2, sort_keys=True, allow_nan=False, default=str))
    else:
        print(text)


def _strict(o: Any) -> Any:
    """``o`` with numpy values as Python ones and non-finite floats as None, in nested dicts/lists."""
    if hasattr(o, "tolist") and not isinstance(o, (str, bytes)):
        o = o.tolist()  # numpy arrays and scalars
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _strict(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_strict(v) for v in o]
    return o


def fail(args: argparse.Namespace, code: int, message: str, word: str = "error: ") -> int:
    """Tell the user why the command stops: one line on stderr (``arboretum CMD: error: MESSAGE``) and,
    under ``--json``, ``{"command", "error", "exit"}`` on stdout too, so a script that reads stdout as
    JSON gets JSON whatever happened; returns ``code``. ``word``: "" for an interruption."""
    command = args.command or ""
    print(f"{f'arboretum {command}'.rstrip()}: {word}{message}", file=sys.stderr, flush=True)
    if getattr(args, "json", False):
        _json_failure(command or "arboretum", message, code)
    return code


def _json_failure(command: str, message: str, code: int) -> None:
    try:
        print(json.dumps({"command": command, "error": message, "exit": code}, indent=2, sort_keys=True), flush=True)
    except BrokenPipeError:  # nobody reads stdout any more: the stderr line stands alone
        pass


def main(argv: list[str] | None = None) -> int:
    words = sys.argv[1:] if argv is None else argv
    try:
        parser = build_parser(_first_word(words))
        _Parser.json_errors = "--json" in words
        args = parser.parse_args(argv)
    except KeyboardInterrupt:  # while the commands register (numpy loads): a 28-44-line traceback before
        command = next((w for w in words if not w.startswith("-")), "")
        return fail(argparse.Namespace(command=command, json="--json" in words), 130, "interrupted", word="")
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        return int(args.func(args) or 0)
    except ArboretumError as exc:
        return fail(args, 2, str(exc))
    except KeyboardInterrupt:
        return fail(args, 130, "interrupted", word="")
    except BrokenPipeError:  # output piped into e.g. `head`, which closed early: not an error
        sys.stderr.close()
        return 0
    except OSError as exc:  # a path the user named that cannot be read or written, or a full disk
        if exc.filename is None and exc.errno not in _DISK_ERRNOS:
            raise
        where = f"{exc.filename}: " if exc.filename is not None else ""
        return fail(args, 2, f"{where}{exc.strerror or exc}")


_DISK_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO}
"""OSErrors of the disk, never of the code: a write() or close() on a full disk names no file, yet
deserves one line rather than a traceback."""


if __name__ == "__main__":  # python -m arboretum_library.cli, as the console script (entry.run)
    from arboretum_library.entry import skip_exit_collection

    skip_exit_collection()
    sys.exit(main())
