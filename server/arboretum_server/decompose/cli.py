"""``arboretum decompose SCAN``: decompose a tree scan into HBL examples and store them in a library.

    arboretum decompose scan.xyz --species apple --library lib/ [--main N] [--lobes N]
        [--points 12000] [--height 0.8] [--seed 0] [--reach-weight W] [--save-hbl tree.npz] [--no-labels]
        [--min-points 200] [--json]

A sparse cloud (a photo reconstruction keeps about 120 tree points) needs a lower --min-points and
small --main and --lobes (at most a tenth of the points): ``--min-points 100 --main 3 --lobes 8``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from contextlib import contextmanager

from arboretum_library.checks import check_height, check_seed
from arboretum_library.cli import add_json_flag, counted, emit, tell
from arboretum_library.pointio import UP_CHOICES


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("decompose", help="decompose a tree scan into HBL examples (VRTree 3.4)")
    p.add_argument("scan", help="point cloud file (.xyz/.txt/.ply/.las/.laz/.npy ...)")
    p.add_argument("--species", default="unknown", help="species; picks N_m and N_l from VRTree Table 2")
    p.add_argument("--main", type=int, default=None, metavar="N", help="N_m, number of main branches")
    p.add_argument("--lobes", type=int, default=None, metavar="N", help="N_s = N_l, number of lobes")
    p.add_argument("--library", default=None, metavar="LIB", help="example library to add the examples to")
    p.add_argument("--points", type=int, default=12000, metavar="N", help="downsample to N points (0: all)")
    p.add_argument("--height", type=float, default=0.8, metavar="M",
                   help="output height in metres (0: keep the scan's units and position)")
    p.add_argument("--seed", type=int, default=0, help="seed for downsampling, FPS and k-means")
    p.add_argument("--reach-weight", type=float, default=None, metavar="W",
                   help="main branches: score reach^W x spread^(1-W); 0 for conifers (default: 0 for pine, "
                        "0.5 otherwise)")
    p.add_argument("--up", choices=UP_CHOICES, default="auto", help="up axis of the file")
    p.add_argument("--no-labels", action="store_true", help="ignore leaf/wood labels stored in the file")
    p.add_argument("--save-hbl", default=None, metavar="OUT.npz", help="also save the whole-tree HBL")
    p.add_argument("--min-points", type=int, default=None, metavar="N",
                   help="fewest usable points a tree may have (default 200; down to 10 for a sparse cloud, "
                        "with small --main and --lobes)")
    add_json_flag(p)
    p.set_defaults(func=run)


def _options(args: argparse.Namespace):
    from arboretum_library.errors import InputError

    from .options import DecomposeOptions
    from .preprocess import check_points

    for name in ("main", "lobes"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise InputError(f"--{name} must be at least 1, got {v}")
    if args.points < 0:
        raise InputError(f"--points must not be negative (0: all), got {args.points}")
    check_height(args.height, keep_units=True)
    check_seed(args.seed)
    floor = _min_points_floor()
    if args.min_points is not None and args.min_points < floor:
        raise InputError(f"--min-points must be at least {floor} (the points of one lobe), got {args.min_points}")
    if args.reach_weight is not None and not 0.0 <= args.reach_weight <= 1.0:
        raise InputError(f"--reach-weight must lie in 0..1, got {args.reach_weight}")
    options = DecomposeOptions(
        species=args.species.lower(), n_main=args.main, n_lobes=args.lobes, points=args.points,
        height=args.height or None, seed=args.seed, use_labels=not args.no_labels, reach_weight=args.reach_weight,
        **({} if args.min_points is None else {"min_points": args.min_points}),
    )
    check_points(options, "--points")  # before the scan is read
    return options


def _min_points_floor() -> int:
    """The lowest ``--min-points``: one lobe's points (``preprocess.POINTS_PER_LOBE``). The pipeline
    refuses fewer points for even one lobe; from there up it works on sparse clouds (measured: the
    bundled scans thinned to 20-150 points decompose with --main 1 --lobes 2, or from 100 points with
    --main 3 --lobes 8; some thinned clouds have no trunk base, a one-line error)."""
    from .preprocess import POINTS_PER_LOBE

    return POINTS_PER_LOBE


def _check_usable(scan: str, cloud, options) -> None:
    """InputError naming ``--min-points`` when the scan holds fewer usable (finite) points than it."""
    import numpy as np

    from arboretum_library.errors import InputError

    n = int(np.isfinite(cloud.points).all(axis=1).sum())  # (N, 3) as read
    if n < options.min_points:
        raise InputError(f"{scan}: {n} usable points, fewer than --min-points {options.min_points}; a sparse "
                         f"cloud can be decomposed with a lower --min-points (at least {_min_points_floor()}) "
                         "and small --main and --lobes")


def run(args: argparse.Namespace) -> int:
    from arboretum_library.outputs import check_output
    from arboretum_library.pointio import ReadOptions, read_points
    from arboretum_library.progress import StatusLine

    from .notes import notes

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    options = _options(args)
    if args.save_hbl:  # before the scan is read; never the scan itself
        check_output(args.save_hbl, "--save-hbl", inputs=[args.scan], suffixes=(".npz",), libraries=[args.library])
    t0 = time.perf_counter()
    cloud = read_points(args.scan, ReadOptions(up=args.up))
    t_read = time.perf_counter() - t0
    _check_usable(args.scan, cloud, options)
    status = StatusLine() if not args.json else (lambda *a: None)
    with _library(args.library) as lib:  # opened first: a library that cannot be written fails before the work
        dec = _decompose(args.scan, cloud, options, status)
        if args.save_hbl:
            _save_hbl(args.save_hbl, dec.hbl)
        examples, stored = _store(lib, dec, args.scan, options)
    data = {
        "scan": args.scan, "points_read": len(cloud.points), "stats": dec.stats,
        "timing_s": {"read": t_read, **dec.timing}, "examples": [e.id for e in examples],
        "stored": stored, "library": str(args.library) if lib is not None else None, "hbl": args.save_hbl,
        "options": options.as_dict(), "notes": notes(options, dec.stats),
    }
    emit(args, data, _text(data))
    return 0


@contextmanager
def _library(path: str | None):
    """The library at ``path`` (None: no library), created if missing; a library this run created is
    removed again when the run fails (a refused scan leaves no empty library behind)."""
    if not path:
        yield None
        return
    from arboretum_library.store import Library

    created = not os.path.exists(path)
    try:
        # a decomposition takes seconds: wait for another writer as long as it takes, saying so
        with Library.open(path, create=True, lock_timeout=None, on_wait=tell) as lib:
            yield lib
    except BaseException:
        if created:
            shutil.rmtree(path, ignore_errors=True)
        raise


def _decompose(scan: str, cloud, options, status):
    from arboretum_library.errors import InputError

    from .pipeline import decompose

    try:
        return decompose(cloud.points, options, status, labels=cloud.labels)
    except InputError as exc:
        raise InputError(f"{scan}: {exc}") from None


def _save_hbl(path: str, hbl) -> None:
    from arboretum_library.codec import save_record
    from arboretum_library.errors import InputError

    try:
        save_record(path, hbl)
    except OSError as exc:
        raise InputError(f"--save-hbl {path}: cannot write it ({exc.strerror or exc})") from None


def _store(lib, dec, scan: str, options) -> tuple[list, list[str]]:
    """(examples, ids stored): a tree goes into ``lib`` whole or not at all (``Library.add_new`` picks
    the ids under the write lock and takes back what it stored when a write fails or Ctrl-C comes)."""
    from .examples import counter_ids, make_examples, provenance

    prov = provenance(scan, options)
    if lib is None:
        return make_examples(dec.hbl, prov, counter_ids("example")), []
    stem = os.path.splitext(os.path.basename(scan))[0]
    examples = lib.add_new(make_examples(dec.hbl, prov), stem)
    return examples, [e.id for e in examples]


def _text(d: dict) -> str:
    s = d["stats"]
    steps = ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in d["timing_s"].items())
    lines = [
        f"{d['scan']}: {d['points_read']} points read, {s['points']} used, {s['leaf_points']} leaf, "
        f"{s['ground_removed']} ground removed",
        f"graph: {counted(s['components'], 'component')} joined by {counted(s['bridges'], 'bridge')}",
        f"HBL: {s['main_branches']} main branches, {s['lobes']} lobes ({s['alpha_shapes']} alpha shapes, "
        f"{s['hull_fallbacks']} convex fallbacks), foliage from {s['foliage_source']}",
        f"time: {steps} (total {sum(d['timing_s'].values()):.2f} s)",
    ]
    if d["library"]:
        lines.append(f"stored {counted(len(d['stored']), 'example')} in {d['library']}: {', '.join(d['stored'])}")
    else:
        lines.append(f"{counted(len(d['examples']), 'example')} made (not stored: no --library given)")
    if d["hbl"]:
        lines.append(f"whole-tree HBL saved to {d['hbl']}")
    lines += [f"note: {n}" for n in d["notes"]]
    return "\n".join(lines)
