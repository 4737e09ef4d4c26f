"""``build_library``: decompose many scans on a Dask cluster; the calling process alone writes the library.

Order of work:

1. Every scan is hashed (SHA-256 of its bytes) in the client. A scan whose examples are all in the
   library already (``Library.find_source`` finds as many as its provenance's ``scan_examples``) is
   skipped; a scan found only in part (a build killed while storing it) has those examples deleted and
   is done again. Scans of equal content given twice are done once.
2. One task per remaining scan (``tasks.decompose_scan``) goes to the cluster: a ``LocalCluster`` of
   ``workers`` single-threaded processes, or the scheduler at ``scheduler`` (``tcp://HOST:8786``).
3. As each future completes, the client stores that scan's examples (each write atomic, under the
   library's lock), so killing the build loses only the scans still in flight. Writes are not fsynced
   one by one (one ``os.sync`` at the end): a process kill loses nothing stored, and after a power
   loss a torn example folder is quarantined when the library is next opened, which makes its scan
   incomplete, so the next build does it again.

A scan that cannot be read, is empty or holds no tree is reported (``ScanRecord.error``) and skipped.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from arboretum_library.errors import InputError
from arboretum_library.pointio import READERS
from arboretum_library.pointio_formats import sniff_not_points
from arboretum_library.progress import ProgressFn, no_progress

from .tasks import (
    MALLOC_STATIC,
    NOTES_KEY,
    SCAN_EXAMPLES_KEY,
    WORKER_CONFIG,
    WORKER_ENV,
    ScanOutcome,
    decompose_scan,
)


@dataclass(frozen=True)
class BuildOptions:
    """How ``build_library`` runs."""

    species: str | None = None
    """Species of every scan; None: a species name found in the file name (e.g. 'apple_03.ply'), else
    'unknown'. Picks N_m and N_l (VRTree Table 2)."""
    workers: int = 2
    """Worker processes of the LocalCluster (ignored with ``scheduler``)."""
    scheduler: str | None = None
    """Address of an existing Dask scheduler, e.g. 'tcp://10.0.0.5:8786'; None starts a LocalCluster."""
    points: int = 12000
    """Decomposition: downsample each scan to this many points (VRTree: 12,000; 0 keeps all)."""
    height: float = 0.8
    """Decomposition: output height, metres (VRTree: 0.8)."""
    seed: int = 0
    """Decomposition seed (downsampling, FPS, k-means)."""

    def __post_init__(self) -> None:
        if self.workers < 1:
            raise InputError(f"--workers must be at least 1, got {self.workers}")
        if self.scheduler is not None and "://" not in self.scheduler:
            raise InputError(f"--scheduler must be an address like tcp://HOST:8786, got {self.scheduler!r}")


@dataclass
class ScanRecord:
    """What happened to one scan in a build."""

    path: str
    species: str
    status: str = "pending"
    """'added', 'skipped' (already in the library), 'duplicate' (same bytes as another scan given) or 'failed'."""
    sha256: str = ""
    examples: list[str] = field(default_factory=list)
    """Library ids of its examples (added now, or found when skipped)."""
    error: str = ""
    seconds: dict[str, float] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    """The decomposition's notes (a second trunk, a straight line, all foliage, counts not met)."""


@dataclass
class BuildResult:
    """A whole build: one record per scan given, in the order given."""

    library: str
    records: list[ScanRecord]
    wall_seconds: float = 0.0
    cluster: str = ""
    workers: int = 0
    redone: int = 0
    """Scans found only in part and done again."""
    ignored: list[tuple[str, str]] = field(default_factory=list)
    """(path, why) of the files left out as recognisably not point clouds (``expand_scans``)."""

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.records)


def expand_scans(paths: list[str], ignored: list[tuple[str, str]] | None = None) -> list[str]:
    """Files as given; folders replaced by their point-cloud files (known suffixes), sorted. Files that
    are recognisably not point clouds (``sniff_not_points``: a TreeQSM cylinder table, a licence) are
    left out and appended to ``ignored`` as (path, why). ``InputError`` for a path that does not exist."""
    out: list[str] = []
    left_out: list[tuple[str, str]] = []
    for p in paths:
        path = Path(p)
        if path.is_dir():
            files = [f for f in sorted(path.iterdir()) if f.is_file() and f.suffix.lower() in READERS]
        elif path.exists():
            files = [path]
        else:
            raise InputError(f"SCAN {p}: no such file or folder")
        for f in files:
            name, why = str(f) if path.is_dir() else str(p), sniff_not_points(f)
            if why is None:
                out.append(name)
            else:
                left_out.append((name, why))
    if not out:
        reason = f": {left_out[0][0]} {left_out[0][1]}" if left_out else " (the folders hold no point-cloud files)"
        raise InputError(f"no scans given{reason}")
    if ignored is not None:
        ignored.extend(left_out)
    return out


def species_for(path: str, given: str | None) -> str:
    """``given`` (lower case), else the first VRTree/harmonic species named in the file name, else 'unknown'."""
    if given:
        return given.lower()
    from arboretum_server.decompose.options import SPECIES_COUNTS

    known = sorted({*SPECIES_COUNTS, "oak", "birch"}, key=len, reverse=True)
    name = Path(path).name.lower()
    return next((s for s in known if s in name), "unknown")


def build_library(scans: list[str], library: str | os.PathLike, options: BuildOptions = BuildOptions(),
                  progress: ProgressFn = no_progress) -> BuildResult:
    """Decompose ``scans`` into examples stored in ``library`` (created if missing); see the module doc."""
    from arboretum_library.store import Library

    t0 = time.perf_counter()
    ignored: list[tuple[str, str]] = []
    records = [ScanRecord(p, species_for(p, options.species)) for p in expand_scans(scans, ignored)]
    result = BuildResult(str(library), records, ignored=ignored)
    with Library.open(library, create=True, fsync=False) as lib:
        todo = _plan(lib, records, result)
        progress(0, max(len(todo), 1), _status(result, 0, len(todo)))
        try:
            if todo:
                _run_cluster(lib, todo, options, result, progress)
        finally:
            os.sync()  # one flush for the whole build instead of one per file
    result.wall_seconds = time.perf_counter() - t0
    return result


def _plan(lib, records: list[ScanRecord], result: BuildResult) -> list[ScanRecord]:
    """Hash every scan; mark failed/skipped/duplicate ones; clear partly stored scans. Returns the rest."""
    from arboretum_server.decompose.examples import file_sha256

    seen: set[str] = set()
    todo = []
    for r in records:
        try:
            r.sha256 = file_sha256(r.path)
        except OSError as exc:
            r.status, r.error = "failed", f"cannot read the file ({exc.strerror or exc})"
            continue
        if r.sha256 in seen:
            r.status = "duplicate"
            continue
        seen.add(r.sha256)
        ids = lib.find_source(r.sha256)
        if ids and _complete(lib, ids):
            r.status, r.examples = "skipped", list(ids)
            r.notes = list(lib.provenance(ids[0]).parameters.get(NOTES_KEY, []))
            continue
        for id_ in ids:  # a build was killed while storing this scan: start it again
            lib.delete(id_)
        result.redone += bool(ids)
        todo.append(r)
    return todo


def _complete(lib, ids: list[str]) -> bool:
    want = lib.provenance(ids[0]).parameters.get(SCAN_EXAMPLES_KEY)
    return want is None or len(ids) >= int(want)


def _run_cluster(lib, todo: list[ScanRecord], o: BuildOptions, result: BuildResult,
                 progress: ProgressFn) -> None:
    from distributed import as_completed

    with _Cluster(o) as (client, name, n_workers):
        result.cluster, result.workers = name, n_workers
        by_key, futures = {}, []
        for r in todo:
            opts = {"species": r.species, "points": o.points, "height": o.height, "seed": o.seed}
            fut = client.submit(decompose_scan, r.path, r.sha256, opts, key=f"decompose-{r.sha256}")
            by_key[fut.key] = r
            futures.append(fut)
        try:
            for done, fut in enumerate(as_completed(futures), 1):
                _store(lib, by_key[fut.key], _outcome(fut))
                fut.release()
                progress(done, len(todo), _status(result, done, len(todo)))
        except BaseException:
            client.cancel(futures, force=True)
            raise


def _outcome(fut) -> ScanOutcome | str:
    try:
        return fut.result()
    except Exception as exc:  # the worker died (KilledWorker) or the task could not run
        return " ".join(f"{type(exc).__name__}: {exc}".split())[:500]


def _store(lib, r: ScanRecord, out: ScanOutcome | str) -> None:
    if isinstance(out, str):
        r.status, r.error = "failed", out
        return
    r.seconds, r.stats, r.notes = out.seconds, out.stats, list(out.notes)
    if out.error:
        r.status, r.error = "failed", out.error
        return
    stem = "".join(c if c.isalnum() or c in "-_" else "-" for c in Path(r.path).stem) or "scan"
    r.examples.extend(e.id for e in lib.add_new(out.examples, stem))  # ids picked under the lock, all or none
    r.status = "added"


def _status(result: BuildResult, done: int, total: int) -> str:
    failed = result.count("failed")
    return f"building {done}/{total} scans" + (f" ({failed} failed)" if failed else "")


class _Cluster:
    """Context manager: (dask Client, description, worker count) on a LocalCluster or a scheduler."""

    def __init__(self, o: BuildOptions) -> None:
        self.o = o
        self.cluster: Any = None
        self.client: Any = None
        self.hidden: dict[str, str] = {}

    def __enter__(self) -> tuple[Any, str, int]:
        from distributed import Client, LocalCluster

        if self.o.scheduler:
            try:
                self.client = Client(self.o.scheduler, timeout="5s")
            except OSError as exc:
                raise InputError(f"cannot reach the Dask scheduler at {self.o.scheduler} ({exc})") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            return self.client, self.o.scheduler, n
        import dask

        # Replaces Dask's worker environment: its MALLOC_TRIM_THRESHOLD_ made decompose 2.5x slower (tasks.py).
        # Workers inherit this process's environment, where an earlier default LocalCluster's nanny may
        # have left that variable (nannies os.environ.update() their pre-spawn environment): hide it.
        self.hidden = {k: os.environ.pop(k) for k in MALLOC_STATIC if k in os.environ}
        with dask.config.set({"distributed.nanny.pre-spawn-environ": dict(WORKER_ENV), **WORKER_CONFIG}), \
                _workers_ignore_sigint():
            self.cluster = LocalCluster(n_workers=self.o.workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None)
        self.client = Client(self.cluster)
        return self.client, "LocalCluster", self.o.workers

    def __exit__(self, kind, *exc) -> None:
        if kind is not None and issubclass(kind, KeyboardInterrupt):
            # Ctrl-C: the workers are stopped, killed when busy in a task; Dask's warnings about that
            # ("Worker process still alive after 4.0 seconds, killing") say nothing to the user
            import logging

            logging.getLogger("distributed").setLevel(logging.CRITICAL)
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        os.environ.update(self.hidden)


@contextlib.contextmanager
def _workers_ignore_sigint() -> Iterator[None]:
    """Ignore SIGINT while LocalCluster starts its worker processes, which keep ignoring it (an ignored
    signal stays ignored across exec and Python then installs no KeyboardInterrupt handler): Ctrl-C in
    the terminal reaches the whole process group, and only the client should handle it (cancel, shut the
    cluster down) instead of every worker printing a KeyboardInterrupt traceback. A Ctrl-C during the
    few seconds of start-up is lost. Outside the main thread (where signals cannot be set) a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)

