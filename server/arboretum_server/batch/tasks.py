"""What a Dask worker runs for one scan: read, decompose, split into examples. Never touches the library.

``decompose_scan`` returns a ``ScanOutcome`` in every case: a scan that cannot be read, is empty or holds
no tree comes back with ``error`` set instead of raising, so one bad scan never fails the build.
Examples come back with placeholder ids; the client gives them library ids when it stores them.
"""

from __future__ import annotations

import gc
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from arboretum_library.model import Example
from arboretum_server.decompose.examples import NOTES_KEY as NOTES_KEY
from arboretum_server.decompose.examples import SCAN_EXAMPLES_KEY as SCAN_EXAMPLES_KEY
from arboretum_server.decompose.examples import UP_AXIS_KEY

THREAD_ENV = {
    "OMP_WAIT_POLICY": "PASSIVE",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
}
"""Environment of every worker: one BLAS/OpenMP thread per task, no spin-waiting (docs/batch.md)."""
WORKER_ENV = dict(THREAD_ENV)
"""The whole environment LocalCluster workers start with; it replaces Dask's default, which sets
``MALLOC_TRIM_THRESHOLD_=65536``. Setting that variable at all (or any other ``MALLOC_*_`` tunable) turns
off glibc's dynamic mmap threshold, so every large numpy array is mmapped and unmapped afresh and its pages
faulted in again: ``decompose`` ran 2.5x slower with 65536 and still 1.25x slower with 128 MiB than in a
plain process (0.47 s against 0.38 s a scan with two workers busy, measured; docs/batch.md)."""
MALLOC_STATIC = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_MMAP_MAX_")
"""The glibc tunables whose setting turns the dynamic mmap threshold off; LocalCluster workers start without."""
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "5s",
    "distributed.worker.preload": ["arboretum_server.batch.tasks"],
}
"""Dask settings of LocalCluster workers: no statistical profiler (it samples the task's stack every
10 ms) and slower housekeeping ticks; together about 8 % of a scan's time on this machine (measured).
The preload runs ``dask_setup`` in every worker."""


def dask_setup(worker: Any) -> None:
    """Run by Dask in each LocalCluster worker as it starts (``WORKER_CONFIG``'s preload): Ctrl-C is the
    client's to handle (it cancels the tasks and shuts the cluster down), so a worker ignores SIGINT (it
    is started with SIGINT blocked: ``signals.sigint_waits``) and does not warn about the
    tasks cancelled then ("Async instruction ... ended with CancelledError"). It also has the worker
    freeze its heap after its first scan (``_freeze_once``)."""
    import logging
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker.state_machine").setLevel(logging.ERROR)
    _GC["freeze"] = True


_GC = {"freeze": False, "frozen": False}
"""``freeze``: set in LocalCluster workers (``dask_setup``), where ``decompose_scan`` freezes the garbage
collector's view of the heap after the worker's first task (``_freeze_once``); ``frozen``: done."""


def _freeze_once() -> None:
    """Move every object alive after the worker's first task (the imports of decompose, scipy, sklearn,
    numba, distributed: ~200,000 objects) out of the garbage collector's reach (``gc.freeze``), once.
    The worker process then exits in 0.04 s instead of 0.3-0.5 s (Python's collections at exit walked
    them all), and closing the cluster, which the build waits for, took 0.1 s instead of 0.7-1.6 s
    (docs/batch.md). The first task's cyclic garbage is collected first; frozen objects are still freed
    when their last reference goes unless they sit in a reference cycle (a one-off, bounded leak of the
    first task's leftovers; later tasks are not frozen). Only in LocalCluster workers: a library function leaves another
    process's collector alone."""
    if _GC["freeze"] and not _GC["frozen"]:
        _GC["frozen"] = True
        gc.collect()
        gc.freeze()


@dataclass(frozen=True)
class ScanOutcome:
    """The result of one scan's task."""

    path: str
    """The scan file as given."""
    sha256: str
    """Hex SHA-256 of its bytes."""
    examples: tuple[Example, ...] = ()
    """Its examples, with placeholder ids ``scan-000`` ...; empty on error."""
    error: str = ""
    """One-line reason the scan was skipped ('' on success)."""
    seconds: dict[str, float] = field(default_factory=dict)
    """Wall times on the worker: read, decompose, examples, total."""
    stats: dict[str, Any] = field(default_factory=dict)
    """points_read and the decomposition's statistics."""
    notes: tuple[str, ...] = ()
    """What the decomposition did that its user may not expect (``decompose.notes``)."""
    worker_pid: int = 0
    """Process id of the worker that ran it."""


def decompose_scan(path: str, sha256: str, options: dict[str, Any]) -> ScanOutcome:
    """Decompose the scan at ``path`` with ``DecomposeOptions(**options)``; never raises for bad input."""
    for k, v in THREAD_ENV.items():
        os.environ.setdefault(k, v)
    t0 = time.perf_counter()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # scikit-learn brings threadpoolctl; without it rely on THREAD_ENV
        out = _run(path, sha256, options, t0)
    else:
        with threadpool_limits(limits=1):
            out = _run(path, sha256, options, t0)
    _freeze_once()
    return out


def _run(path: str, sha256: str, options: dict[str, Any], t0: float) -> ScanOutcome:
    from arboretum_library.errors import ArboretumError

    try:
        return _decompose(path, sha256, options, t0)
    except ArboretumError as exc:
        return _failed(path, sha256, without_path(str(exc), path), t0)
    except (MemoryError, RecursionError, ValueError, FloatingPointError, IndexError, RuntimeError,
            OSError, ArithmeticError, TypeError, KeyError) as exc:  # a scan the pipeline cannot handle
        return _failed(path, sha256, f"{type(exc).__name__}: {exc}", t0)


def without_path(message: str, path: str) -> str:
    """``message`` without the leading "'PATH': " that the point readers put first (``pointio``): the
    build's line and its record name the scan already ("failed: PATH: 1 point(s) have NaN ...")."""
    for name in dict.fromkeys((path, str(Path(path)))):  # the reader names it as a Path: ./a.xyz is a.xyz
        prefix = f"'{name}': "
        if message.startswith(prefix):
            return message[len(prefix):]
    return message


def _failed(path: str, sha256: str, message: str, t0: float) -> ScanOutcome:
    line = " ".join(message.split())[:500]
    return ScanOutcome(path, sha256, error=line, seconds={"total": time.perf_counter() - t0},
                       worker_pid=os.getpid())


def _decompose(path: str, sha256: str, options: dict[str, Any], t0: float) -> ScanOutcome:
    from arboretum_library.errors import InputError
    from arboretum_library.pointio import precision_note, read_points
    from arboretum_server.decompose.examples import counter_ids, make_examples, provenance
    from arboretum_server.decompose.notes import (
        bare_note,
        refusal,
        result_notes,
        up_doubts,
        up_guess_flat,
        upside_down_note,
    )
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    opts = DecomposeOptions(**options)
    cloud = read_points(path)
    t_read = time.perf_counter()
    if why := up_guess_flat(cloud.points, "auto", cloud.up_axis):  # a wall in a Z-up file
        return _failed(path, sha256, f"{why}: a build reads every scan with --up auto; if Z is up in the file, "
                       "decompose it alone: arboretum decompose SCAN --up z --library LIB", t0)
    # the file's own precision, kept with the notes; by file name: the build's line names the path, and a
    # refusal is cut at 500 characters
    coarse = precision_note(replace(cloud, source=os.path.basename(path)), points=opts.points)
    doubt = up_doubts(cloud, "auto", build=True)  # a trunk-like top and no ground; a LAS shaped another way
    try:
        dec = decompose(cloud.points, opts, labels=cloud.labels)
    except InputError as exc:  # on a coarse grid the refusal names the symptom: say the cause too
        return _failed(path, sha256, refusal(str(exc), coarse, exc, doubt), t0)
    t_dec = time.perf_counter()
    prov = provenance(path, opts, sha256=sha256)
    prov = replace(prov, parameters={**prov.parameters, UP_AXIS_KEY: cloud.up_axis})  # as decompose keeps it
    examples = make_examples(dec.hbl, prov, counter_ids("scan"))
    if not examples:
        return _failed(path, sha256, "decomposition gave no examples (no main branch found)", t0)
    said = result_notes(opts, dec.stats)  # the species note would repeat for every scan of a species
    way = [n for n in (upside_down_note("auto", cloud.up_axis, build=True), doubt) if n]  # kept with the notes
    said = way + ([coarse] if coarse else []) + said
    params = {**prov.parameters, SCAN_EXAMPLES_KEY: len(examples), NOTES_KEY: list(said)}
    # examples without lobes: said when made, not stored with the notes (the user may delete those
    # examples, and a rerun would repeat a stale count); placeholder ids, so none named
    said += [bare] if (bare := bare_note(examples)) else []
    examples = [replace(e, provenance=replace(e.provenance, parameters=params)) for e in examples]
    t_end = time.perf_counter()
    seconds = {"read": t_read - t0, "decompose": t_dec - t_read, "examples": t_end - t_dec, "total": t_end - t0}
    stats = {"points_read": len(cloud.points), **dec.stats}
    return ScanOutcome(path, sha256, tuple(examples), "", seconds, stats, tuple(said), os.getpid())
