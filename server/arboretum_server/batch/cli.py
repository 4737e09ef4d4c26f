"""``arboretum library build``: decompose many scans in parallel (Dask) into an example library.

    arboretum library build SCANS... --library LIB [--species S] [--workers N]
        [--scheduler tcp://HOST:8786 [--worker-timeout S]] [--report DIR] [--recursive] [--rebuild]
        [--points 12000] [--height 0.8] [--seed 0] [--leaf-off] [--json]

SCANS are files or folders (every point-cloud file inside, and with --recursive in the folders below;
files that are recognisably not point clouds, such as TreeQSM cylinder tables, are left out with a
note). Run it again after an interruption: scans already in the library are skipped (examples deleted
since stay deleted; a note says when they were made with other options); --rebuild decomposes them
again with this run's options and replaces their examples. Without --species, a scan's species is the
one species its file name names as a word (oak_03.ply: oak; pinewood_oak.ply: oak). Exit status: 0 when
every scan was stored (or already there), 1 when any scan failed (the others are stored), 2 for a
mistake in the arguments, 130 after Ctrl-C, 143 after SIGTERM (stopped as Ctrl-C stops it). A library
this build created is removed again when nothing was stored in it. See docs/batch.md.
"""

from __future__ import annotations

import argparse

from arboretum_library.checks import check_height, check_seed, check_species
from arboretum_library.cli import add_json_flag, emit


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``build`` action to the ``library`` command's sub-parsers ``sub``."""
    p = sub.add_parser("build", help="decompose many scans in parallel (Dask) into a library",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scans", nargs="+", metavar="SCAN", help="scan files, or folders of them")
    p.add_argument("--library", required=True, metavar="LIB", help="library to add to (created if missing)")
    p.add_argument("--species", help="species of every scan (default: from each file name, else unknown)")
    p.add_argument("--workers", type=int, default=2, metavar="N", help="local worker processes (default 2)")
    p.add_argument("--scheduler", metavar="tcp://HOST:8786", help="use this running Dask scheduler instead")
    p.add_argument("--report", metavar="DIR", help="report folder (default: LIB-report next to LIB)")
    p.add_argument("--points", type=int, default=12000, metavar="N", help="downsample each scan (0: all)")
    p.add_argument("--height", type=float, default=0.8, metavar="M", help="output height in metres (0: keep each scan's units and position)")
    p.add_argument("--seed", type=int, default=0, help="decomposition seed")
    p.add_argument("--leaf-off", action="store_true",
                   help="every scan is of a tree without leaves: report all points as wood")
    p.add_argument("--recursive", action="store_true", help="folders: read the folders below them too")
    p.add_argument("--rebuild", action="store_true",
                   help="decompose scans already in the library again, replacing their examples")
    p.add_argument("--worker-timeout", type=float, metavar="S",
                   help="with --scheduler: give up after S seconds without any worker (default: wait)")
    add_json_flag(p)
    p.set_defaults(func=run)


def check_args(args: argparse.Namespace) -> str:
    """InputError naming the option for a bad argument, before any scan is read or worker started (the
    checks of ``arboretum decompose``). Returns the report folder."""
    from pathlib import Path

    from arboretum_library.errors import InputError
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.preprocess import check_points

    if args.points < 0:
        raise InputError(f"--points must not be negative (0: all), got {args.points}")
    check_height(args.height)  # as decompose: 0 keeps the scan's units
    check_seed(args.seed)
    check_species(args.species)
    check_points(DecomposeOptions(points=args.points), "--points")
    folder = args.report or f"{str(Path(args.library)).rstrip('/')}-report"
    if Path(folder).exists() and not Path(folder).is_dir():
        raise InputError(f"--report {folder}: is a file; the report is a folder (give a new or existing folder)")
    lib = Path(args.library)
    if lib.exists() and not lib.is_dir():
        raise InputError(f"--library {lib}: is a file, not a library folder")
    if Path(folder).resolve().is_relative_to(lib.resolve()):  # a build that stores nothing removes the library
        raise InputError(f"--report {folder}: is inside --library {lib}; keep the report beside the library")
    return folder


def run(args: argparse.Namespace) -> int:
    """The command; SIGTERM stops it as Ctrl-C does, then exits 143 (128 + SIGTERM) with one line."""
    from arboretum_library.cli import fail

    from .signals import Terminated, sigterm_stops

    folder = check_args(args)
    with sigterm_stops():
        try:
            return _build(args, folder)
        except Terminated:
            return fail(args, 143, "interrupted (SIGTERM)", word="")


def _build(args: argparse.Namespace, folder: str) -> int:
    import os
    from pathlib import Path

    from arboretum_library.progress import StatusLine

    from .build import BuildOptions, build_library
    from .report import as_dict, write_report

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    opts = BuildOptions(species=args.species, workers=args.workers, scheduler=args.scheduler,
                        points=args.points, height=args.height or None, seed=args.seed, leaf_off=args.leaf_off, rebuild=args.rebuild,
                        recursive=args.recursive, worker_timeout=args.worker_timeout)
    status = StatusLine() if not args.json else _waiting_on_stderr()
    created = not Path(args.library).exists()
    try:
        result = build_library(args.scans, args.library, opts, status)
    except BaseException:
        if created:
            drop_if_empty(args.library)
        raise
    files = write_report(result, folder)
    dropped = created and drop_if_empty(args.library)
    data = {**as_dict(result), "report": files, "library_kept": not dropped}
    emit(args, data, _text(data))
    return 1 if result.count("failed") else 0


def drop_if_empty(library: str) -> bool:
    """Remove the library folder when it holds no example (a build that created it stored nothing);
    whether it was removed."""
    import shutil
    from pathlib import Path

    root = Path(library)
    examples = root / "examples"
    if not (root / "library.json").is_file() or (examples.is_dir() and any(examples.iterdir())):
        return False
    shutil.rmtree(root, ignore_errors=True)
    return True


def _waiting_on_stderr():
    """With --json (no status line): a progress function printing only "waiting: ..." to stderr, once."""
    import sys

    said: set[str] = set()

    def progress(done: int, total: int, message: str = "") -> None:
        if message.startswith("waiting") and message not in said:
            said.add(message)
            print(message, file=sys.stderr, flush=True)

    return progress


def _text(d: dict) -> str:
    from arboretum_library.cli import counted

    redone = f"; {d['redone']} of them done again: --rebuild, or damaged" if d.get("redone") else ""
    lines = [f"{d['library']}: {counted(d['added'], 'scan')} added ({counted(d['examples_added'], 'example')}{redone}), "
             f"{d['skipped']} already there, {counted(d['duplicate'], 'duplicate')}, {d['failed']} failed, "
             f"in {d['wall_seconds']:.1f} s on {counted(d['workers'], 'worker')} ({d['cluster'] or 'no cluster needed'})"]
    lines += [f"  note: {n}" for n in d.get("notes", [])]
    lines += [f"  failed: {r['path']}: {r['error']}" for r in d["records"] if r["status"] == "failed"]
    lines += [f"  note: {r['path']}: {n}" for r in d["records"] for n in r["notes"]]
    lines += [f"  left out: {i['path']}: {i['why']}" for i in d.get("ignored", [])]
    if not d.get("library_kept", True):
        lines.append(f"  nothing was stored: the library {d['library']} this build created was removed")
    lines.append(f"report: {d['report'].get('markdown', '')}")
    return "\n".join(lines)
