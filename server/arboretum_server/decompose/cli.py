"""``arboretum decompose SCAN``: decompose a tree scan into HBL examples and store them in a library.

    arboretum decompose scan.xyz --species apple --library lib/ [--main N] [--lobes N]
        [--points 12000] [--height 0.8] [--seed 0] [--reach-weight W] [--save-hbl tree.npz] [--no-labels]
        [--leaf-off] [--min-points 200] [--rebuild] [--json]

A scan already in LIB (the same bytes, decomposed with the same options) is not stored again: the run
names the examples there and stores nothing; --rebuild decomposes it again and replaces them (as
``arboretum library build --rebuild`` does).

Ctrl-C (exit 130) or SIGTERM (exit 143) takes back what the run stored and removes a library it created;
one that comes after the examples are committed waits for the report, and the run exits 0.

A sparse cloud (a photo reconstruction keeps about 120 tree points) needs a lower --min-points and
small --main and --lobes (at most a tenth of the points): ``--min-points 100 --main 3 --lobes 8``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import time
from contextlib import ExitStack, contextmanager
from dataclasses import replace

from arboretum_library.checks import check_height, check_seed, check_species
from arboretum_library.cli import add_json_flag, counted, emit, fail, tell
from arboretum_library.pointio import SCAN_UP_CHOICES
from arboretum_library.signals import held


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
    p.add_argument("--seed", type=int, default=0, help="seed for downsampling and k-means")
    p.add_argument("--reach-weight", type=float, default=None, metavar="W",
                   help="main branches: score reach^W x spread^(1-W); 0 for conifers (default: 0 for pine, "
                        "0.5 otherwise)")
    p.add_argument("--up", choices=SCAN_UP_CHOICES, default="auto",
                   help="the way up of the file: auto (default), z, y, or z-down / y-down for a file standing "
                   "upside down")
    p.add_argument("--no-labels", action="store_true", help="ignore leaf/wood labels stored in the file")
    p.add_argument("--leaf-off", action="store_true",
                   help="the tree bore no leaves when scanned: report every point as wood (the geometry is the "
                        "same; see docs/decomposition.md)")
    p.add_argument("--save-hbl", default=None, metavar="OUT.npz", help="also save the whole-tree HBL")
    p.add_argument("--min-points", type=int, default=None, metavar="N",
                   help="fewest usable points a tree may have (default 200; down to 10 for a sparse cloud, "
                        "with small --main and --lobes)")
    p.add_argument("--rebuild", action="store_true",
                   help="the scan is in --library already (same file, same options): decompose it again and "
                        "replace its examples (default: store nothing)")
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
    check_height(args.height)
    check_seed(args.seed)
    check_species(args.species)
    floor = _min_points_floor()
    if args.min_points is not None and args.min_points < floor:
        raise InputError(f"--min-points must be at least {floor} (the points of one lobe), got {args.min_points}")
    if args.reach_weight is not None and not 0.0 <= args.reach_weight <= 1.0:
        raise InputError(f"--reach-weight must lie in 0..1, got {args.reach_weight}")
    options = DecomposeOptions(
        species=args.species.lower(), n_main=args.main, n_lobes=args.lobes, points=args.points,
        height=args.height or None, seed=args.seed, use_labels=not args.no_labels, reach_weight=args.reach_weight,
        leaf_off=args.leaf_off,
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
    """The command; SIGTERM stops it as Ctrl-C does (what the run stored is taken back, a library it created
    removed), then exits 143 (128 + SIGTERM) with one line, as ``library build`` does."""
    from arboretum_server.batch.signals import Terminated, sigterm_stops

    with sigterm_stops():
        try:
            return _run(args)
        except Terminated:
            return fail(args, 143, "interrupted (SIGTERM)", word="")


def _run(args: argparse.Namespace) -> int:
    from arboretum_library.outputs import check_output
    from arboretum_library.pointio import ReadOptions, precision_note, read_points
    from arboretum_library.progress import StatusLine

    from .examples import UP_AXIS_KEY, file_sha256, provenance
    from .notes import bare_note, notes, up_doubts, upside_down_note

    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    options = _options(args)
    if args.save_hbl:  # before the scan is read; never the scan itself
        check_output(args.save_hbl, "--save-hbl", inputs=[args.scan], suffixes=(".npz",), libraries=[args.library])
    t0 = time.perf_counter()
    cloud = read_points(args.scan, ReadOptions(up=args.up))
    t_read = time.perf_counter() - t0
    _check_usable(args.scan, cloud, options)
    _check_up(args.scan, cloud, args.up)
    prov = provenance(args.scan, options, sha256=file_sha256(args.scan))
    prov = replace(prov, parameters={**prov.parameters, UP_AXIS_KEY: cloud.up_axis})  # --up y is another tree
    status = StatusLine() if not args.json else (lambda *a: None)
    with ExitStack() as done:
        with _library(args.library) as lib:  # opened first: a library that cannot be written fails before the work
            there, other = _stored(lib, prov)
            if there and not args.rebuild and not args.save_hbl:  # nothing to do: no decomposition either
                data = _result(args, options, len(cloud.points), {"read": t_read}, None, ([], [], there), other)
                data["notes"] += [surplus] if (surplus := _surplus(lib, there)) else []
                emit(args, data, _text(data))
                return 0
            coarse = precision_note(cloud, points=options.points)  # float32 at UTM: the points sit on a 0.5 m grid
            doubt = up_doubts(cloud, args.up)  # a trunk-like top and no ground; a LAS shaped another way
            dec = _decompose(args.scan, cloud, options, status, coarse, doubt)
            if args.save_hbl:
                _save_hbl(args.save_hbl, dec.hbl)
            stored = _store(lib, dec, args.scan, prov, args.rebuild)
            # stored and committed: the run is done, a Ctrl-C or SIGTERM from here on only waits for the report
            late = done.enter_context(held(signal.SIGINT, signal.SIGTERM))
        data = _result(args, options, len(cloud.points), {"read": t_read, **dec.timing}, dec, stored, other)
        bare = bare_note(stored[0], named=bool(stored[1]))  # library ids name them; example-000 would not
        way = [n for n in (upside_down_note(args.up, cloud.up_axis), doubt) if n]
        data["notes"] = way + ([coarse] if coarse else []) + notes(options, dec.stats) + data["notes"] \
            + ([bare] if bare else [])
        emit(args, data, _text(data))
    if late:
        tell(f"arboretum {args.command}: {'Ctrl-C' if late[0] == signal.SIGINT else 'SIGTERM'} came after the "
             "run had finished: its result stands")
    return 0


def _result(args, options, points_read: int, timing: dict, dec, stored: tuple, other: list[str]) -> dict:
    """The run's JSON-ready result; ``stored`` is ``_store``'s (examples, ids stored, ids there already),
    ``dec`` None when the scan was not decomposed (already in the library)."""
    examples, ids, there = stored
    said = [f"the library also holds {counted(len(other), 'example')} of this file made with other options "
            f"({_ids(other)}): kept"] if other else []
    return {
        "scan": args.scan, "points_read": points_read, "stats": dec.stats if dec is not None else {},
        "timing_s": timing, "examples": [e.id for e in examples], "stored": ids,
        "already": [] if args.rebuild else there, "replaced": there if args.rebuild and ids else [],
        "library": str(args.library) if args.library else None, "hbl": args.save_hbl if dec is not None else None,
        "options": options.as_dict(), "notes": said,
    }


def _check_up(scan: str, cloud, up: str) -> None:
    """InputError when ``--up auto`` turned the file so that all its points lie at one height (a vertical
    wall in a Z-up file reads as Y up): said so, with ``--up z``, instead of the decomposition's "all
    points lie at one height", false for the file as written."""
    from arboretum_library.errors import InputError

    from .notes import up_guess_flat

    if why := up_guess_flat(cloud.points, up, cloud.up_axis):
        raise InputError(f"{scan}: {why}: if Z is up in the file, pass --up z")


def _stored(lib, prov) -> tuple[list[str], list[str]]:
    """(ids, other ids) of the examples in ``lib`` from the scan of ``prov``, by its SHA-256 (as
    ``library build`` finds a scan), split by whether they were made with the same species, options and
    up axis (``examples.run_key``). ([], []) without a library."""
    from .examples import split_runs

    if lib is None or not prov.source_sha256:
        return [], []
    return split_runs(lib, sorted(lib.find_source(prov.source_sha256)), prov)


def _surplus(lib, ids: list[str]) -> str | None:
    """A note when ``lib`` holds more examples of one scan and options (``ids``) than one run makes (a
    ``--rebuild`` stopped between storing the new examples and deleting the old ones), else None."""
    from .examples import SCAN_EXAMPLES_KEY

    if lib is None or not ids:
        return None
    made = lib.provenance(ids[0]).parameters.get(SCAN_EXAMPLES_KEY)
    if not isinstance(made, int) or len(ids) <= made:
        return None
    return (f"the library holds {len(ids)} examples of this file made with these options, where one run makes "
            f"{made} (a --rebuild stopped half-way?); --rebuild replaces them all")


def _ids(ids: list[str]) -> str:
    """Up to 8 of ``ids``, then '...'."""
    return ", ".join(ids[:8]) + (", ..." if len(ids) > 8 else "")


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


def _decompose(scan: str, cloud, options, status, coarse: str | None, doubt: str | None):
    from arboretum_library.errors import InputError

    from .notes import refusal
    from .pipeline import decompose

    try:
        return decompose(cloud.points, options, status, labels=cloud.labels)
    except InputError as exc:
        raise InputError(refusal(f"{scan}: {exc}", coarse, exc, doubt)) from None


def _save_hbl(path: str, hbl) -> None:
    from arboretum_library.codec import save_record
    from arboretum_library.errors import InputError

    try:
        save_record(path, hbl)
    except OSError as exc:
        raise InputError(f"--save-hbl {path}: cannot write it ({exc.strerror or exc})") from None


def _store(lib, dec, scan: str, prov, rebuild: bool) -> tuple[list, list[str], list[str]]:
    """(examples, ids stored, ids of the scan already there with the same options): a tree goes into
    ``lib`` whole or not at all (``Library.add_new`` picks the ids under the write lock and takes back
    what it stored when a write fails or Ctrl-C comes). A scan already there is not stored again; with
    ``rebuild`` its new examples are stored, then the old ones deleted, in one hold of the lock (as
    ``library build --rebuild``: a failure keeps the old ones)."""
    from .examples import SCAN_EXAMPLES_KEY, counter_ids, make_examples

    if lib is None:
        return make_examples(dec.hbl, prov, counter_ids("example")), [], []
    stem = os.path.splitext(os.path.basename(scan))[0]
    with lib.locked():  # checked again: another writer may have stored it while this run decomposed
        there, _ = _stored(lib, prov)
        if there and not rebuild:
            return make_examples(dec.hbl, prov, counter_ids("example")), [], there
        made = make_examples(dec.hbl, prov)
        counted_prov = replace(prov, parameters={**prov.parameters, SCAN_EXAMPLES_KEY: len(made)})
        examples = lib.add_new([replace(e, provenance=counted_prov) for e in made], stem)
        for id_ in there:
            if id_ in lib:
                lib.delete(id_)
    return examples, [e.id for e in examples], there


def _text(d: dict) -> str:
    s = d["stats"]
    if not s:  # already in the library: not decomposed
        return "\n".join([f"{d['scan']}: {d['points_read']} points read", *_stored_lines(d)])
    steps = ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in d["timing_s"].items())
    return "\n".join([
        f"{d['scan']}: {d['points_read']} points read, {s['points']} used, {_leaves(s)}, "
        f"{s['ground_removed']} ground removed",
        f"graph: {counted(s['components'], 'component')} joined by {counted(s['bridges'], 'bridge')}",
        f"HBL: {s['main_branches']} main branches, {s['lobes']} lobes ({counted(s['alpha_shapes'], 'alpha shape')}, "
        f"{counted(s['hull_fallbacks'], 'convex fallback')}), foliage from {s['foliage_source']}",
        f"time: {steps} (total {sum(d['timing_s'].values()):.2f} s)",
        *_stored_lines(d),
    ])


def _leaves(s: dict) -> str:
    """'N leaf', or for a declared leaf-off tree what the separation still found (it steers the routing)."""
    if s["labels"] == "leaf-off":
        return f"0 leaf (declared leaf-off; {s['fine_wood_points']} points of fine wood)"
    return f"{s['leaf_points']} leaf"


def _stored_lines(d: dict) -> list[str]:
    """What went into the library (or why nothing did), the HBL file, the notes."""
    if d["already"]:
        lines = [f"already in {d['library']} as ids {_ids(d['already'])} (this file, decomposed with the same "
                 "options): nothing stored; --rebuild decomposes it again and replaces them"]
    elif d["library"]:
        lines = [f"stored {counted(len(d['stored']), 'example')} in {d['library']}: {', '.join(d['stored'])}"
                 + (f"; replaced {_ids(d['replaced'])} (--rebuild)" if d["replaced"] else "")]
    else:
        lines = [f"{counted(len(d['examples']), 'example')} made (not stored: no --library given)"]
    if d["hbl"]:
        lines.append(f"whole-tree HBL saved to {d['hbl']}")
    return lines + [f"note: {n}" for n in d["notes"]]
