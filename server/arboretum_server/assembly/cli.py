"""``arboretum assemble SCRIPT --library LIB --out SESSION``: headless assembly from a script.

The script (JSON or YAML) is a list of operations, or a map with ``ops:`` (and optionally ``name:``).
Each operation is a one-key map, run by the same handlers as the server, in-process::

    - add: {example: ex-0001, as: trunk, at: [0, 0, 0], rotate_z: 30, scale: 1.0}
    - transform: {instance: trunk, at: [0.1, 0, 0], rotate: [0, 0, 1, 45]}
    - transform_lobe: {instance: trunk, lobe: 2, at: [0, 0.1, 0], scale: 1.3}
    - sketch: {as: top, strokes: [[[0, 0, 2], [0, 0, 3]], [[0.2, 0, 3], [0, 0.2, 3], [-0.2, 0, 3], [0.2, 0, 3]]]}
    - delete: {instance: top}
    - undo: {}
    - redo: {}
    - export: {out: tree.glb, seed: 0, lod: 0, options: {density: 0.5}}

A transform is ``T`` (a 4x4 matrix) or ``at`` (translation, metres), ``rotate`` ([axis x, y, z, degrees])
or ``rotate_z`` (degrees) and ``scale``; ``transform`` and ``transform_lobe`` keep the current value of
each of them left out. The whole script is checked before it runs (``script_check``); exports and
``--out`` are written aside and moved into place only once every operation succeeded, all or none
(``script.swap``): a Ctrl-C (held back meanwhile) or a file that cannot be replaced leaves the old
files or the new ones, never a mix.
``--out`` writes the session (an Assembly record, .npz; another suffix is refused).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from arboretum_library.cli import add_json_flag, emit


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("assemble", help="build an assembly headlessly from a JSON/YAML script")
    p.add_argument("script", help="JSON or YAML list of operations (see docs/server.md)")
    p.add_argument("--library", required=True, metavar="LIB", help="example library")
    p.add_argument("--out", required=True, metavar="SESSION", help="session file to write (.npz)")
    p.add_argument("--from", dest="start", default=None, metavar="SESSION", help="start from a saved session")
    add_json_flag(p)
    p.set_defaults(func=run)


def read_script(path: str | Path) -> tuple[str, list[dict]]:
    """(session name, operations) of a JSON or YAML script; ``InputError`` describing any problem."""
    import json

    import yaml

    from arboretum_library.checks import check_input_file
    from arboretum_library.errors import InputError

    p = check_input_file(str(path), "script")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a text file; the script must be JSON or YAML text") from None
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else yaml.load(text, Loader=yaml_loader())
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else str(exc).splitlines()[0]
        raise InputError(f"{p}: not valid {'JSON' if p.suffix.lower() == '.json' else 'YAML'} ({where})") from None
    name, ops = "", data
    if isinstance(data, dict):
        if "ops" in data and (extra := sorted(str(k) for k in data if k not in ("name", "ops"))):
            raise InputError(f"{p}: unknown key {extra[0]!r}; a script map takes name and ops")
        name, ops = str(data.get("name", "")), data.get("ops")
    if not isinstance(ops, list) or not all(isinstance(o, dict) and len(o) == 1 for o in ops):
        raise InputError(f"{p}: expected a list of one-key maps such as '- add: {{example: ID}}'")
    return name, ops


def yaml_loader():
    """PyYAML's safe loader, reading numbers such as ``1e-3`` or ``1e300`` as numbers (YAML 1.2) where
    plain PyYAML (YAML 1.1) reads them as text: ``scale: 1e-3`` is a number in a script."""
    import yaml

    from arboretum_library.yaml12 import with_yaml12_numbers

    return with_yaml12_numbers(yaml.SafeLoader)


def open_library(path: str | Path):
    """The library at ``path`` opened for reading (a script only reads examples, so neither its lock nor
    write access is needed); a writing open only to rebuild a missing or damaged catalog
    (``Library.open_reading``). ``InputError`` naming ``--library`` when it cannot be opened."""
    import sqlite3

    from arboretum_library.errors import ArboretumError, InputError
    from arboretum_library.store import Library

    try:
        return Library.open_reading(path)
    except InputError as exc:
        raise InputError(f"--library: {exc}") from None
    except (ArboretumError, OSError, sqlite3.Error) as exc:
        why = f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) and exc.filename else str(exc)
        raise InputError(f"--library {path}: cannot open the library ({why})") from None


def run(args: argparse.Namespace) -> int:
    import tempfile

    from arboretum_library.assembly import Assembly
    from arboretum_library.atomic import interruptible
    from arboretum_library.codec import load_record, save_record
    from arboretum_library.outputs import check_output
    from arboretum_library.progress import StatusLine

    from .script import Runner
    from .script_check import check_ops

    # --out may be the --from session: it is read whole first and replaced atomically at the end (the
    # demo continues a session in place); the script and the library's files must never be overwritten
    check_output(args.out, inputs=[args.script], suffixes=(".npz",), libraries=[args.library])
    name, ops = read_script(args.script)
    # the whole script is checked before anything runs: a mistake in any operation writes nothing
    checked = check_ops(ops, inputs=[args.script, args.start], outputs=[args.out], libraries=[args.library])
    start = load_record(args.start, Assembly) if args.start else None
    library = open_library(args.library)  # read-only: the runner's context closes it
    with tempfile.TemporaryDirectory(prefix="arboretum-assemble-") as state:
        runner = Runner(Path(args.library), Path(state), name, start, opened=library)
        try:
            results = [runner.run(op, None if args.json else StatusLine()) for op in checked]
            assembly = runner.assembly()
            with interruptible():  # a Ctrl-C waits: --out and every export are replaced together, or none
                runner.stage(Path(args.out), "--out", lambda tmp: save_record(tmp, assembly))
                runner.commit()  # and so does a file that cannot be replaced (script.swap)
        finally:
            runner.close()
    data: dict[str, Any] = {
        "out": args.out, "operations": results, "placements": [p.instance for p in assembly.placements],
        "merges": [[m.a, m.b, m.vertex_a, m.vertex_b] for m in assembly.merges],
        "sketches": [s.id for s in assembly.sketches],
    }
    text = "\n".join(r["label"] for r in results) + (
        f"\nwrote {args.out}: {len(assembly.placements)} placements, {len(assembly.merges)} merges")
    emit(args, data, text)
    return 0
