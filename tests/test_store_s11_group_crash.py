"""A run stored with ``add_new`` is seen whole or not at all: by a reader while it is written (its rows
are committed in one transaction), and after the writer is killed at a random moment (the next writer
rolls an unfinished run back, its rows again in one transaction).

Run as a script (``python test_store_s11_group_crash.py LIB``) this file is the writer: it stores runs
of ``RUN`` examples with fsync on until it is killed.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RUN = 3


def expected(n: int) -> list:
    """The examples of run ``n`` (0-based), as they are given to ``add_new``."""
    from factories import make_example

    rng = np.random.default_rng(1000 + n)
    return [make_example(rng, id="x", n_lobes=1 + j) for j in range(RUN)]


def _writer(path: str) -> None:
    from arboretum_library.store import Library

    lib = Library.open(path, create=True, fsync=True)
    print("ready", flush=True)
    while True:
        lib.add_new(expected(len(lib) // RUN), "run")


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    _writer(sys.argv[1])
    raise SystemExit(0)

from arboretum_library.store import Library  # noqa: E402
from factories import assert_examples_equal, run_then_kill  # noqa: E402


def _check_whole(root: Path) -> int:
    """Reopen as a writer: whole runs only, each example as written, .tmp/ empty. Returns the count."""
    with Library.open(root) as lib:
        ids = lib.ids()
        assert len(ids) % RUN == 0 and ids == [f"run-{i:04d}" for i in range(1, len(ids) + 1)]
        assert sorted(p.name for p in (root / "examples").iterdir()) == ids
        assert list((root / ".tmp").iterdir()) == []
        for n in range(len(ids) // RUN):
            for j, ex in enumerate(expected(n)):
                id_ = f"run-{n * RUN + j + 1:04d}"
                assert_examples_equal(lib.get(id_), replace(ex, id=id_))
        return len(ids)


def _read_counts(root: Path, stop: threading.Event, seen: list[int]) -> None:
    while not (root / "catalog.sqlite").exists():
        time.sleep(0.01)
    with Library.open(root, readonly=True) as ro:
        while not stop.is_set():
            seen.append(len(ro.ids()))


def test_runs_are_seen_whole_while_written_and_after_the_writer_is_killed(tmp_path):
    root = tmp_path / "lib"
    stop, seen = threading.Event(), []
    reader = threading.Thread(target=_read_counts, args=(root, stop, seen))
    counts = [0]
    try:
        for i, delay in enumerate(np.random.default_rng(11).uniform(0.2, 0.6, 4)):
            run_then_kill(__file__, root, delay, reader.start if i == 0 else None)
            counts.append(_check_whole(root))
            assert counts[-1] >= counts[-2], counts
    finally:
        stop.set()
        reader.join(10)
    assert counts[-1] >= 2 * RUN, counts
    assert len(seen) > 100 and {c % RUN for c in seen} == {0}, sorted(set(seen))
