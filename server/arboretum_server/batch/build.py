"""``build_library``: decompose many scans on a Dask cluster; the calling process alone writes the library.

Order of work:

1. Every scan is hashed (SHA-256 of its bytes) in the client. A scan with examples in the library
   already (``Library.find_source``) is skipped, its record naming what is stored, with notes when
   examples were deleted since, were made with other options, or a file of the same name with other
   contents has examples too (``plan.py``); with ``rebuild`` it is done again instead. Scans of equal
   content given twice are done once.
2. One task per remaining scan (``tasks.decompose_scan``) goes to the cluster: a ``LocalCluster`` of
   ``workers`` single-threaded processes, or the scheduler at ``scheduler`` (``tcp://HOST:8786``).
3. As each future completes, the client stores that scan's examples (all or none, ``Library.add_new``,
   under the library's lock), so killing the build loses only the scans still in flight. A scan done
   again (``rebuild``, damaged) has its new examples stored first, under fresh ids, and its old ones
   deleted after them under the same lock hold, so a failure keeps the old ones (``plan.py``). Writes
   are not fsynced one by one (one ``os.sync`` at the end): a process kill loses nothing stored. After a
   power loss, a torn folder without a catalog row is quarantined when the library is next opened and
   one whose files are not the size its row records is seen by the plan: either way the next build does
   its scan again. One torn at its right size is found only when read; ``arboretum library delete`` it
   and build its scan again with ``rebuild``.

A scan that cannot be read, is empty or holds no tree is reported (``ScanRecord.error``) and skipped.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from arboretum_library.checks import check_number
from arboretum_library.errors import InputError
from arboretum_library.progress import ProgressFn, no_progress

from .plan import plan, scan_stem
from .scans import expand_scans
from .signals import sigint_waits, sigterm_waits
from .tasks import MALLOC_STATIC, WORKER_CONFIG, WORKER_ENV, ScanOutcome, decompose_scan
from .waiting import Waiting, completed

__all__ = ["BuildOptions", "BuildResult", "ScanRecord", "build_library", "expand_scans", "species_for",
           "species_guess"]


@dataclass(frozen=True)
class BuildOptions:
    """How ``build_library`` runs."""

    species: str | None = None
    """Species of every scan; None: the one species the file name names as a word (``species_guess``:
    'apple_03.ply' -> apple), else 'unknown'. Picks N_m and N_l (VRTree Table 2)."""
    workers: int = 2
    """Worker processes of the LocalCluster (ignored with ``scheduler``)."""
    scheduler: str | None = None
    """Address of an existing Dask scheduler, e.g. 'tcp://10.0.0.5:8786'; None starts a LocalCluster."""
    points: int = 12000
    """Decomposition: downsample each scan to this many points (VRTree: 12,000; 0 keeps all)."""
    height: float | None = 0.8
    """Decomposition: output height, metres (VRTree: 0.8); None keeps each scan's units and position
    (``arboretum library build --height 0``, as ``decompose``'s)."""
    seed: int = 0
    """Decomposition seed (downsampling, FPS, k-means)."""
    leaf_off: bool = False
    """Decomposition: every scan is of a leafless tree; report all points wood (``DecomposeOptions.leaf_off``)."""
    rebuild: bool = False
    """Decompose scans already in the library again (this run's options), replacing their examples."""
    recursive: bool = False
    """Folders given: take the point-cloud files of every folder below them too."""
    worker_timeout: float | None = None
    """With ``scheduler`` only: give up (``InputError``) when the scheduler has had no worker for this
    many seconds; None waits. (A LocalCluster has no worker only while one is restarted.)"""

    def __post_init__(self) -> None:
        if self.workers < 1:
            raise InputError(f"--workers must be at least 1, got {self.workers}")
        check_number(self.worker_timeout, "--worker-timeout", 0.0, math.inf, lo_open=True)
        if self.worker_timeout is not None and self.scheduler is None:
            raise InputError("--worker-timeout applies only with --scheduler (a local cluster always has "
                             "its --workers); leave it out or give --scheduler tcp://HOST:8786")
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
    """The decomposition's notes (a second trunk, a straight line, all foliage, counts not met), and
    the build's about what is stored (``plan.py``)."""
    replace: list[str] = field(default_factory=list)
    """Ids of stored examples of this scan that its new examples replace (``rebuild``, damaged)."""


@dataclass
class BuildResult:
    """A whole build: one record per scan given, in the order given."""

    library: str
    records: list[ScanRecord]
    wall_seconds: float = 0.0
    cluster: str = ""
    workers: int = 0
    redone: int = 0
    """Scans in the library done again and stored (``rebuild``, or examples of it found damaged)."""
    ignored: list[tuple[str, str]] = field(default_factory=list)
    """(path, why) of the files left out as recognisably not point clouds, and of subfolders holding
    point clouds not read (``expand_scans``)."""
    notes: list[str] = field(default_factory=list)
    """Notes on the build's options, said once rather than for every scan (an implausible --height)."""

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.records)


GUESSED = ("oak", "birch")
"""Species guessed from file names besides those of VRTree Table 2 (``SPECIES_COUNTS``)."""


def species_for(path: str, given: str | None) -> str:
    """``given`` (lower case), else ``species_guess``'s species."""
    return given.lower() if given else species_guess(path)[0]


def species_guess(path: str) -> tuple[str, str]:
    """(species, note) from the file name: the species that its words name ('' note), else 'unknown'
    (with a note when it names several). Words are the runs of letters of the name without its suffix,
    split where a lower-case letter meets a capital ('OakTree', 'PineScan'), case folded, so a species
    inside a longer word is no species ('pinewood', 'Pinecrest', 'pineapple'); a plural counts ('oaks',
    'birches', 'cherries')."""
    import re

    from arboretum_server.decompose.options import SPECIES_COUNTS

    words = {form: s for s in (*SPECIES_COUNTS, *GUESSED) for form in (s, _plural(s))}
    found: list[str] = []
    camel = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", Path(path).stem)  # OakTree_01: Oak, Tree
    for word in re.findall(r"[^\W\d_]+", camel.casefold()):
        if word in words and words[word] not in found:
            found.append(words[word])
    if len(found) == 1:
        return found[0], ""
    if not found:
        return "unknown", ""
    return "unknown", (f"its file name names {len(found)} species ({', '.join(found)}): none guessed, so "
                       "'unknown' (N_m = 8, N_l = 40); rename the file, or build it alone with --species")


def _plural(word: str) -> str:
    """The English plural of a species name: birches, cherries, oaks."""
    if word.endswith(("s", "x", "z", "ch", "sh")):
        return f"{word}es"
    if word.endswith("y") and word[-2:-1] not in "aeiou":
        return f"{word[:-1]}ies"
    return f"{word}s"


def build_library(scans: list[str], library: str | os.PathLike, options: BuildOptions = BuildOptions(),
                  progress: ProgressFn = no_progress) -> BuildResult:
    """Decompose ``scans`` into examples stored in ``library`` (created if missing); see the module doc."""
    from arboretum_library.store import Library
    from arboretum_server.decompose.notes import height_notes

    t0 = time.perf_counter()
    ignored: list[tuple[str, str]] = []
    files = expand_scans(scans, ignored, options.recursive)
    records = [_record(p, options.species) for p in files]
    result = BuildResult(str(library), records, ignored=ignored, notes=height_notes(options.height))
    with Library.open(library, create=True, fsync=False) as lib:
        todo = plan(lib, records, options)
        progress(0, max(len(todo), 1), _status(result, 0, len(todo)))
        try:
            if todo:
                _run_cluster(lib, todo, options, result, progress)
        finally:
            os.sync()  # one flush for the whole build instead of one per file
    result.redone = sum(bool(r.replace) and r.status == "added" for r in records)
    result.wall_seconds = time.perf_counter() - t0
    return result


def _record(path: str, species: str | None) -> ScanRecord:
    """The record of one scan to build, its species given or guessed (with a note when no guess)."""
    if species:
        return ScanRecord(path, species.lower())
    guess, note = species_guess(path)
    return ScanRecord(path, guess, notes=[note] if note else [])


def _run_cluster(lib, todo: list[ScanRecord], o: BuildOptions, result: BuildResult,
                 progress: ProgressFn) -> None:
    with _Cluster(o) as (client, name, n_workers):
        result.cluster, result.workers = name, n_workers
        by_key, futures = {}, []
        for r in todo:
            opts = {"species": r.species, "points": o.points, "height": o.height, "seed": o.seed,
                    "leaf_off": o.leaf_off}
            fut = client.submit(decompose_scan, r.path, r.sha256, opts, key=f"decompose-{r.sha256}")
            by_key[fut.key] = r
            futures.append(fut)
        try:
            waiting = Waiting(client, o.scheduler, o, progress, lambda d, t: _status(result, d, t))
            for done, fut in enumerate(completed(futures, waiting), 1):
                _store(lib, by_key[fut.key], _outcome(fut))
                fut.release()
                progress(done, len(todo), _status(result, done, len(todo)))
            result.workers = result.workers or len(client.nthreads())  # workers that joined late
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
    r.seconds, r.stats, r.notes = out.seconds, out.stats, [*out.notes, *r.notes]  # the plan's notes last
    if out.error:
        r.status, r.error = "failed", out.error
        return
    with lib.locked():  # no other writer between storing the new examples and deleting the old
        # all or none, under fresh ids (the old ones still exist): a failure here leaves the old intact
        r.examples.extend(e.id for e in lib.add_new(out.examples, scan_stem(r.path)))
        r.status = "added"
        for id_ in r.replace:  # its examples of an earlier build (rebuild, damaged), deleted only now
            if id_ in lib:
                lib.delete(id_)


def _status(result: BuildResult, done: int, total: int) -> str:
    failed = result.count("failed")
    return f"building {done}/{total} scans" + (f" ({failed} failed)" if failed else "")


PROBE_SECONDS = 5.0
"""How long ``_probe`` waits for a ``--scheduler`` address to connect and to speak first."""


def _probe(address: str) -> None:
    """InputError unless what listens at a tcp:// ``address`` speaks within ``PROBE_SECONDS``: a Dask
    scheduler sends its handshake as it accepts a connection, while Dask's client waits for it with no
    deadline (distributed 2026.8, ``comm.core.connect``), so a port that accepted and never answered hung
    the build for good (helper-134). Other protocols, and addresses that refuse or cannot be reached, are
    left to Dask's own errors."""
    import socket
    from urllib.parse import urlsplit

    if "://" in address and not address.startswith("tcp://"):
        return
    try:
        url = urlsplit(address if "://" in address else f"tcp://{address}")
        host, port = url.hostname, url.port
    except ValueError:
        return
    if not host:
        return
    try:
        sock = socket.create_connection((host, port or 8786), timeout=PROBE_SECONDS)  # Dask's default port
    except OSError:  # refused, unreachable, or no answer to the connection itself: Dask says which
        return
    with sock:
        try:
            sock.settimeout(PROBE_SECONDS)
            sock.recv(1)
        except TimeoutError:
            raise InputError(f"--scheduler {address}: nothing answered within {PROBE_SECONDS:g} s; a Dask "
                             "scheduler speaks as soon as it accepts a connection") from None
        except OSError:
            return


class _Cluster:
    """Context manager: (dask Client, description, worker count) on a LocalCluster or a scheduler."""

    def __init__(self, o: BuildOptions) -> None:
        self.o = o
        self.cluster: Any = None
        self.client: Any = None
        self.hidden: dict[str, str] = {}

    def __enter__(self) -> tuple[Any, str, int]:
        try:
            return self._start()
        except BaseException as exc:  # e.g. a SIGTERM that waited for the start: what started is stopped
            self.__exit__(type(exc), exc, exc.__traceback__)
            raise

    def _start(self) -> tuple[Any, str, int]:
        from distributed import Client, LocalCluster

        if self.o.scheduler:
            _probe(self.o.scheduler)
            try:
                self.client = Client(self.o.scheduler, timeout="5s")
            except OSError as exc:
                raise InputError(f"cannot reach the Dask scheduler at {self.o.scheduler} ({exc})") from None
            except Exception as exc:  # noqa: BLE001 - an answer Dask cannot read: a 3 EiB MemoryError for HTTP
                raise InputError(f"--scheduler {self.o.scheduler}: what answers there is not a Dask scheduler "
                                 f"({type(exc).__name__})") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            return self.client, self.o.scheduler, n
        import dask

        # Replaces Dask's worker environment: its MALLOC_TRIM_THRESHOLD_ made decompose 2.5x slower (tasks.py).
        # Workers inherit this process's environment, where an earlier default LocalCluster's nanny may
        # have left that variable (nannies os.environ.update() their pre-spawn environment): hide it.
        self.hidden = {k: os.environ.pop(k) for k in MALLOC_STATIC if k in os.environ}
        with dask.config.set({"distributed.nanny.pre-spawn-environ": dict(WORKER_ENV), **WORKER_CONFIG}), \
                sigint_waits(), sigterm_waits():
            # no dashboard; the scheduler's HTTP server (health, metrics) on a free port, so that another
            # cluster on port 8787 brings no "Port 8787 is already in use" warning
            self.cluster = LocalCluster(n_workers=self.o.workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None,
                                        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
            self.client = Client(self.cluster)
        return self.client, "LocalCluster", self.o.workers

    def __exit__(self, kind, *exc) -> None:
        """Close the client and the cluster with SIGINT and SIGTERM held: cut short, the close left the
        cluster to the interpreter's exit, its workers outliving their scheduler. On a stop (Ctrl-C, SIGTERM)
        a signal that comes during the close is dropped, so the close completes (a second Ctrl-C); otherwise
        it is raised after it."""
        import signal

        from arboretum_library.signals import held

        stopping = kind is not None and issubclass(kind, KeyboardInterrupt)
        with held(signal.SIGINT, signal.SIGTERM) as got:
            if stopping:
                self._quiet()
            if self.client is not None:
                self.client.close()
            if self.cluster is not None:
                self.cluster.close()
            os.environ.update(self.hidden)
        if got and not stopping:
            signal.raise_signal(got[0])

    def _quiet(self) -> None:
        """After Ctrl-C or SIGTERM (``Terminated``), silence Dask's logging in this process and in the local
        workers: stopping them, Dask logs what says nothing to the user ("Worker process still alive after
        4.0 seconds, killing"; a worker's heartbeat to the scheduler already closed, with a 46-line
        traceback). The workers of a ``scheduler`` are not ours and keep their logging."""
        import logging

        for name in DASK_LOGGERS:
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        if self.cluster is None or self.client is None:
            return
        try:  # in each worker's event loop, which answers while a task runs; a worker that does not gives up
            self.client.sync(self.client._run, silence_logging, on_error="ignore", callback_timeout=QUIET_SECONDS)
        except Exception:  # noqa: BLE001 - a worker dead or deaf: the close stops it anyway
            pass


DASK_LOGGERS = ("distributed", "distributed.client", "distributed.gc", "tornado", "tornado.application")
"""The loggers Dask's logging set-up gives a level (``distributed.config``): each must be raised, a child
with its own level is not silenced by its parent's."""
QUIET_SECONDS = 2.0
"""Longest wait for the workers to silence their logging on a stop (measured on 2 workers: 0.05 s idle,
0.2 s with both busy in a numpy task, under a load of 8 on 2 cores)."""


def silence_logging() -> None:
    """Run in a worker process being stopped: no more log records, whatever their logger or level."""
    import logging

    logging.disable(logging.CRITICAL)
