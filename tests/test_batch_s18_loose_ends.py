"""``library build`` (session 18): a stop silences Dask and cannot be cut short by a second signal;
--height as ``decompose`` takes it; a scan's read error names its path once."""

from __future__ import annotations

import logging
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.cli import main
from arboretum_library.pointio import write_points
from arboretum_server.batch import build, tasks
from arboretum_server.batch.build import BuildOptions, _Cluster
from arboretum_server.batch.cli import _text
from arboretum_server.batch.signals import Terminated, sigterm_stops


@pytest.fixture
def cloud(tmp_path) -> Path:
    rng = np.random.default_rng(3)
    return write_points(tmp_path / "c.xyz", np.c_[rng.normal(0, 0.3, (500, 2)), rng.uniform(0, 4, 500)])


def _error(capsys) -> str:
    """The one stderr line after "error: " (asserting it is one line, no traceback)."""
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.split("error: ", 1)[1]


# ---------------------------------------------------------------- the shared options


@pytest.mark.parametrize("height", ["-1", "nan", "inf", "-inf", "1e13"])
def test_build_refuses_a_height_with_decompose_s_message(cloud, tmp_path, capsys, height):
    assert main(["decompose", str(cloud), f"--height={height}"]) == 2
    said = _error(capsys)
    lib = tmp_path / "B"
    assert main(["library", "build", str(cloud), "--library", str(lib), f"--height={height}"]) == 2
    assert _error(capsys) == said and not lib.exists()


@pytest.mark.parametrize("extra", [["--points", "-1"], ["--points", "150"], ["--seed", "-1"], ["--species", ""],
                                   ["--species", "  "]])
def test_build_refuses_points_and_seed_with_decompose_s_message(cloud, tmp_path, capsys, extra):
    assert main(["decompose", str(cloud), *extra]) == 2
    said = _error(capsys)
    assert main(["library", "build", str(cloud), "--library", str(tmp_path / "B"), *extra]) == 2
    assert _error(capsys) == said
    if extra[0] == "--species":  # blank: decompose stored the species '', the build guessed from the name
        assert said == f"--species must name a species (or be left out), got {extra[1]!r}\n"


def test_build_height_0_keeps_the_scan_s_units_as_decompose_does(tmp_path, capsys):
    """--height 0 was refused by the build ("must be a finite number > 0") and taken by decompose."""
    rng = np.random.default_rng(0)
    path = tmp_path / "scans" / "tree.xyz"
    path.parent.mkdir()
    n = 2000
    trunk = np.c_[rng.normal(0, 0.05, (n // 2, 2)), rng.uniform(0, 6, n // 2)]
    crown = np.c_[rng.normal(0, 1.5, (n // 2, 2)), rng.uniform(4, 10, n // 2)]
    write_points(path, np.r_[trunk, crown])
    lib = tmp_path / "L"
    code = main(["library", "build", str(path), "--library", str(lib), "--height", "0", "--workers", "1",
                 "--points", "1500", "--json"])
    assert code == 0, capsys.readouterr().err
    from arboretum_library.store import Library

    with Library.open(lib) as library:
        ids = library.ids()
        assert ids and library.provenance(ids[0]).parameters["height"] is None
        spans = [float(np.ptp(np.concatenate([b.points for b in library.get(i).structure.branches]), axis=0).max())
                 for i in ids]
    assert max(spans) > 2.0  # the scan's units (a 10 m tree), not VRTree's 0.8 m


def test_plan_names_a_height_of_none_as_height_0():
    from arboretum_server.batch.plan import _arg

    assert [_arg(None), _arg(0.8)] == [0, 0.8]


# ---------------------------------------------------------------- a scan's error names it once


def test_a_nan_scan_fails_with_its_path_once(tmp_path):
    path = tmp_path / "nan.xyz"
    pts = np.random.default_rng(1).uniform(0, 1, (300, 3))
    pts[7, 1] = np.nan
    np.savetxt(path, pts)
    out = tasks._run(str(path), "x", {"points": 0}, time.perf_counter())
    assert out.error.startswith("1 point(s) have NaN") and str(path) not in out.error
    rec = {"path": str(path), "status": "failed", "error": out.error, "notes": []}
    data = {"library": "L", "added": 0, "examples_added": 0, "skipped": 0, "duplicate": 0, "failed": 1,
            "wall_seconds": 1.0, "workers": 1, "cluster": "LocalCluster", "records": [rec],
            "report": {"markdown": "r.md"}}
    line = next(x for x in _text(data).splitlines() if "failed:" in x)
    assert line.count(str(path)) == 1 and line == f"  failed: {path}: {out.error}"


@pytest.mark.parametrize("path, message, left", [
    ("a/b.xyz", "'a/b.xyz': holds no points", "holds no points"),
    ("./a/b.xyz", "'a/b.xyz': holds no points", "holds no points"),  # the reader names it as a Path
    ("a/b.xyz", "point cloud: 2 usable points", "point cloud: 2 usable points"),
    ("a/b.xyz", "see 'a/b.xyz': later", "see 'a/b.xyz': later"),  # only a leading name
])
def test_without_path(path, message, left):
    assert tasks.without_path(message, path) == left


# ---------------------------------------------------------------- a stop: held signals, quiet workers


class _Closing:
    """A client or cluster whose close() sends this process ``signum`` (the signal comes mid-close)."""

    def __init__(self, log: list, name: str, signum: int | None = None) -> None:
        self.log, self.name, self.signum = log, name, signum

    def close(self) -> None:
        if self.signum is not None:
            os.kill(os.getpid(), self.signum)
            time.sleep(0.05)  # the handler runs in the main thread at the next bytecode
        self.log.append(self.name)


def _cluster(log: list, signum: int | None) -> _Cluster:
    c = _Cluster(BuildOptions())
    c.client, c.cluster = _Closing(log, "client", signum), _Closing(log, "cluster")
    return c


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_the_close_waits_until_the_cluster_is_closed(signum):
    """Before, the signal raised inside client.close() and cluster.close() was never called: the cluster
    was left to the interpreter's exit, its workers outliving the scheduler."""
    log: list[str] = []
    with sigterm_stops(), pytest.raises(KeyboardInterrupt) as caught:  # Terminated is one
        _cluster(log, signum).__exit__(None, None, None)
    assert log == ["client", "cluster"]
    assert (caught.type is Terminated) == (signum == signal.SIGTERM)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_second_signal_during_a_stop_is_dropped(signum, monkeypatch):
    """A second Ctrl-C (or a SIGTERM) while a stop closes the cluster: the close completes."""
    log: list[str] = []
    c = _cluster(log, signum)
    monkeypatch.setattr(_Cluster, "_quiet", lambda self: log.append("quiet"))
    with sigterm_stops():
        assert c.__exit__(KeyboardInterrupt, KeyboardInterrupt(), None) is None
    assert log == ["quiet", "client", "cluster"]


def test_a_normal_close_leaves_dask_s_logging_alone(monkeypatch):
    log: list[str] = []
    monkeypatch.setattr(_Cluster, "_quiet", lambda self: log.append("quiet"))
    _cluster(log, None).__exit__(None, None, None)
    assert log == ["client", "cluster"]


def test_a_stop_silences_the_local_workers_and_no_scheduler_s(monkeypatch):
    from distributed import Client, LocalCluster

    names = list(build.DASK_LOGGERS)
    levels = {n: logging.getLogger(n).level for n in names}
    try:
        with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None, scheduler_port=0) as lc, \
                Client(lc) as client:
            remote = _Cluster(BuildOptions(scheduler="tcp://x:1"))
            remote.client = client  # a scheduler's workers are not ours: left as they are
            remote._quiet()
            assert set(client.run(lambda: logging.root.manager.disable).values()) == {0}
            local = _Cluster(BuildOptions())
            local.client, local.cluster = client, lc
            t0 = time.perf_counter()
            local._quiet()
            assert time.perf_counter() - t0 < build.QUIET_SECONDS
            assert set(client.run(lambda: logging.root.manager.disable).values()) == {logging.CRITICAL}
        assert all(logging.getLogger(n).level > logging.CRITICAL for n in names)
    finally:
        for n, level in levels.items():
            logging.getLogger(n).setLevel(level)
