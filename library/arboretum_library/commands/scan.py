"""``arboretum scan``: look at and convert point cloud files.

``scan info FILE...`` prints counts, extent, height, up axis and point spacing of each file;
``scan convert IN OUT`` reads with the preparation options (up axis, recentre, height, max points) and
writes any writable format. Add a subcommand by writing ``_add_NAME(sub)`` and calling it in ``register``.
"""

from __future__ import annotations

import argparse

from arboretum_library.cli import add_json_flag, emit
from arboretum_library.pointio import SCAN_UP_CHOICES


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("scan", help="inspect and convert point cloud files (scans)")
    sub = parser.add_subparsers(dest="scan_command", metavar="SUBCOMMAND", required=True)
    _add_info(sub)
    _add_convert(sub)


def _add_up(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--up",
        choices=SCAN_UP_CHOICES,
        default="auto",
        help="the way up of the file: auto-detect (default), z, y (converted to Z up), or z-down / y-down "
        "for a file standing upside down (turned the right way up)",
    )


def _add_info(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="print point count, extent, height, up axis and spacing of scans",
        description="Print point count, extent, height, up axis (and the guess) and median point spacing.",
    )
    p.add_argument(
        "files", nargs="+", metavar="FILE", help=".xyz .txt .csv .asc .pts .ply .pcd .las .laz .npy"
    )
    _add_up(p)
    add_json_flag(p)
    p.set_defaults(func=run_info)


def _add_convert(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "convert",
        help="read a scan, prepare it (up axis, recentre, height, thinning) and write it",
        description="Read IN, optionally recentre / scale / thin it, and write OUT (.ply .xyz .txt .npy). "
        "VRTree's preparation is: --recentre --height 0.8 --max-points 12000.",
    )
    p.add_argument("input", metavar="IN", help="point cloud file to read")
    p.add_argument("output", metavar="OUT", help="file to write (.ply .xyz .txt .npy)")
    _add_up(p)
    p.add_argument("--recentre", action="store_true", help="move the trunk base to the origin")
    p.add_argument(
        "--height", type=float, default=None, metavar="M",
        help=f"scale uniformly to this height (m, {MIN_HEIGHT:g} .. {MAX_HEIGHT:g})",
    )
    p.add_argument(
        "--max-points", type=int, default=None, metavar="N", help="thin evenly to at most N points"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the thinning (default 0)")
    add_json_flag(p)
    p.set_defaults(func=run_convert)


def run_info(args: argparse.Namespace) -> int:
    from arboretum_library.pointio import ReadOptions, read_points, scan_stats

    options = ReadOptions(up=args.up)
    stats = [scan_stats(read_points(f, options)) for f in args.files]
    emit(args, stats, "\n\n".join(format_stats(s, args.up) for s in stats))
    return 0


def format_stats(s: dict, up_asked: str = "auto") -> str:
    """Human text of one ``scan_stats`` dict of a file read with ``--up up_asked``."""
    extent = "  ".join(
        f"{a} {lo:.3f} .. {hi:.3f} ({size:.3f} m)"
        for a, lo, hi, size in zip("xyz", s["min"], s["max"], s["size"])
    )
    attrs = [
        name
        for key, name in (
            ("has_colors", "colors"),
            ("has_labels", "labels"),
            ("has_branch_ids", "branch ids"),
        )
        if s[key]
    ]
    lines = [
        s["file"],
        f"  points     {s['points']:,}",
        f"  extent     {extent}",
        f"  height     {s['height']:.3f} m",
        f"  up axis    {_way_up(s['up_axis'])} "
        f"(guess {s['up_guess']}, confidence {s['up_confidence']:.2f}){_las_doubt(s, up_asked)}",
        f"  spacing    {s['spacing'] * 1000:.1f} mm (median nearest-neighbour distance)",
        f"  attributes {', '.join(attrs) if attrs else 'none'}",
    ]
    if "leaf_fraction" in s:
        lines.append(f"  leaf       {s['leaf_fraction'] * 100:.1f}% of points")
    return "\n".join(lines)


def _las_doubt(s: dict, up_asked: str) -> str:
    """For a file read Z up by its format (``pointio.z_up_by_format``: LAS, LAZ) whose shape says another
    way (``up_by_shape``): the option that reads it that way, else ''."""
    from arboretum_library.pointio import z_up_by_format

    if s["up_by_shape"] == "z" or not z_up_by_format(s["file"], up_asked):
        return ""
    return f"; LAS is Z up by its format, so the guess was not applied: pass --up {s['up_by_shape']} if the file is not"


def _way_up(up_axis: str) -> str:
    """The way up a file was read with, as ``scan info`` and ``scan convert`` print it."""
    return up_axis + (": the file stands upside down; turned the right way up" if up_axis.endswith("-down") else "")

MIN_HEIGHT, MAX_HEIGHT = 1e-3, 1e3
"""Range of ``scan convert --height`` in metres: a millimetre to a kilometre covers every tree (and
keeps the scaled coordinates far from float64 overflow)."""


def check_convert(args: argparse.Namespace) -> None:
    """InputError naming the option for a bad ``scan convert`` argument, before the scan is read."""
    import math
    from pathlib import Path

    from arboretum_library.checks import check_seed
    from arboretum_library.errors import InputError
    from arboretum_library.outputs import check_output
    from arboretum_library.pointio import WRITERS

    h = args.height
    if h is not None and not (math.isfinite(h) and MIN_HEIGHT <= h <= MAX_HEIGHT):
        raise InputError(f"--height {h:g}: the target height must be a number > 0, from {MIN_HEIGHT:g} "
                         f"to {MAX_HEIGHT:g} metres")
    if args.max_points is not None and args.max_points < 2:
        raise InputError(f"--max-points must be at least 2, got {args.max_points}")
    check_seed(args.seed)
    suffix = Path(args.output).suffix
    if suffix.lower() not in WRITERS:
        raise InputError(f"OUT '{args.output}': cannot write format '{suffix}' (writable: {' '.join(sorted(WRITERS))})")
    check_output(args.output, "OUT", inputs=[args.input])


def run_convert(args: argparse.Namespace) -> int:
    from arboretum_library.pointio import ReadOptions, read_points, scan_stats, write_points

    check_convert(args)
    options = ReadOptions(
        up=args.up,
        recentre=args.recentre,
        target_height=args.height,
        max_points=args.max_points,
        seed=args.seed,
    )
    cloud = read_points(args.input, options)
    out = write_points(args.output, cloud)
    stats = scan_stats(cloud)
    stats["file"] = str(out)
    stats["input"] = args.input
    doubt = _las_doubt({**stats, "file": args.input}, args.up)
    text = f"wrote {out}: {len(cloud):,} points, height {stats['height']:.3f} m (from {args.input}, up {_way_up(cloud.up_axis)}{doubt})"
    emit(args, stats, text)
    return 0
