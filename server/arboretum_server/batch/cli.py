"""``arboretum library build``: decompose many scans in parallel (Dask) into an example library.

    arboretum library build SCANS... --library LIB [--species S] [--workers N]
        [--scheduler tcp://HOST:8786] [--report DIR] [--points 12000] [--height 0.8] [--seed 0] [--json]

SCANS are files or folders (every point-cloud file inside). Run it again after an interruption: scans
already in the library are skipped. See docs/batch.md.
"""

from __future__ import annotations

import argparse

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
    p.add_argument("--height", type=float, default=0.8, metavar="M", help="output height in metres")
    p.add_argument("--seed", type=int, default=0, help="decomposition seed")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import os
    from pathlib import Path

    from arboretum_library.errors import InputError
    from arboretum_library.progress import StatusLine

    from .build import BuildOptions, build_library
    from .report import as_dict, write_report

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    if args.points < 0 or not args.height > 0:
        raise InputError("--points must be >= 0 and --height > 0")
    opts = BuildOptions(species=args.species, workers=args.workers, scheduler=args.scheduler,
                        points=args.points, height=args.height, seed=args.seed)
    status = StatusLine() if not args.json else (lambda *a: None)
    result = build_library(args.scans, args.library, opts, status)
    folder = args.report or f"{str(Path(args.library)).rstrip('/')}-report"
    files = write_report(result, folder)
    data = {**as_dict(result), "report": files}
    emit(args, data, _text(data))
    return 0


def _text(d: dict) -> str:
    lines = [f"{d['library']}: {d['added']} scans added ({d['examples_added']} examples), {d['skipped']} "
             f"already there, {d['duplicate']} duplicates, {d['failed']} failed, in {d['wall_seconds']:.1f} s "
             f"on {d['workers']} workers ({d['cluster'] or 'no cluster needed'})"]
    lines += [f"  failed: {r['path']}: {r['error']}" for r in d["records"] if r["status"] == "failed"]
    lines += [f"  note: {r['path']}: {n}" for r in d["records"] for n in r["notes"]]
    lines.append(f"report: {d['report'].get('markdown', '')}")
    return "\n".join(lines)
