"""``arboretum library build``: parallel decomposition on a Dask LocalCluster, resumable, bad scans skipped."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.pointio import write_points
from arboretum_library.store import Library
from arboretum_server.batch.build import BuildOptions, build_library, expand_scans, species_for
from arboretum_server.batch.plots import nice_ticks
from arboretum_server.batch.report import _cell, write_report
from arboretum_server.batch.synthetic import synthetic_scans
from arboretum_server.batch.tasks import SCAN_EXAMPLES_KEY
from arboretum_server.decompose.examples import file_sha256
from factories import stubbed_pole

POINTS = 1500
OPTS = BuildOptions(workers=2, points=POINTS)


@pytest.fixture(scope="module")
def scans(tmp_path_factory) -> dict[str, list[Path]]:
    """4 good synthetic scans and 3 bad ones (unparsable, empty, a flat plane that is no tree)."""
    folder = tmp_path_factory.mktemp("scans")
    good = synthetic_scans(folder, 4, points=POINTS)
    (folder / "broken.xyz").write_text("this is not\na point cloud 1 2\n")
    (folder / "empty.xyz").write_text("")
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(-1, 1, (800, 2)), rng.normal(0, 0.002, 800)]
    write_points(folder / "plane.xyz", plane)
    bad = [folder / "broken.xyz", folder / "empty.xyz", folder / "plane.xyz"]
    return {"good": good, "bad": bad, "folder": [folder]}


@pytest.fixture(scope="module")
def built(scans, tmp_path_factory):
    lib = tmp_path_factory.mktemp("lib") / "lib"
    result = build_library([str(p) for p in scans["good"] + scans["bad"]], lib, OPTS)
    return lib, result


def _examples_per_source(lib_path: Path) -> dict[str, list[str]]:
    with Library.open(lib_path, readonly=True) as lib:
        out: dict[str, list[str]] = {}
        for e in lib.entries():
            out.setdefault(e.source_sha256, []).append(e.id)
        return out


def test_build_adds_good_scans_and_reports_bad_ones(built, scans):
    lib, result = built
    status = {Path(r.path).name: r.status for r in result.records}
    assert [status[p.name] for p in scans["good"]] == ["added"] * 4
    assert [status[p.name] for p in scans["bad"]] == ["failed"] * 3
    errors = {Path(r.path).name: r.error for r in result.records if r.status == "failed"}
    assert "empty" in errors["empty.xyz"] and "trunk" in errors["plane.xyz"]
    per_source = _examples_per_source(lib)
    for p in scans["good"]:
        rec = next(r for r in result.records if r.path == str(p))
        assert sorted(per_source[file_sha256(p)]) == sorted(rec.examples) and len(rec.examples) >= 1
        assert rec.seconds["decompose"] > 0 and rec.stats["points"] <= POINTS
    with Library.open(lib, readonly=True) as L:
        assert len(L) == sum(len(r.examples) for r in result.records)
        e = L.entries()[0]
        assert e.species in ("apple", "cherry", "ginkgo", "walnut")
        assert L.get(e.id).provenance.parameters[SCAN_EXAMPLES_KEY] == len(L.find_source(e.source_sha256))
    assert result.workers == 2 and result.cluster == "LocalCluster"


def test_rerun_skips_done_scans_without_a_cluster(built, scans, monkeypatch):
    lib, first = built
    before = _examples_per_source(lib)
    # deciding what is done reads each scan's provenance (meta.json), never its examples' arrays
    monkeypatch.setattr(Library, "get", lambda self, id_: pytest.fail(f"loaded {id_} whole"))
    again = build_library([str(p) for p in scans["good"]], lib, OPTS)
    assert again.count("skipped") == 4 and again.count("added") == 0
    assert again.cluster == "" and again.workers == 0  # nothing left to do: no cluster started
    assert _examples_per_source(lib) == before


def test_damaged_scan_is_redone_and_a_pruned_one_kept(built, scans, tmp_path):
    # a scan's examples are stored all or none (Library.add_new), so fewer than its scan_examples means
    # some were deleted (kept so), or quarantined as torn after a power loss (the scan is done again)
    import shutil

    lib = Path(shutil.copytree(built[0], tmp_path / "lib"))  # a copy of the module's build (it built its own)
    good = [str(p) for p in scans["good"][:2]]
    sha, pruned = file_sha256(good[0]), file_sha256(good[1])
    with Library.open(lib) as L:
        ids, kept = L.find_source(sha), L.find_source(pruned)[1:]
        (lib / "quarantine").mkdir()
        shutil.copytree(lib / "examples" / ids[-1], lib / "quarantine" / f"{ids[-1]}-12345678")
        L.delete(ids[-1])
        L.delete(L.find_source(pruned)[0])  # the user prunes an example
    again = build_library(good, lib, OPTS)
    assert again.redone == 1 and again.count("added") == 1 and again.count("skipped") == 1
    assert len(_examples_per_source(lib)[sha]) == len(ids) and _examples_per_source(lib)[pruned] == kept


def test_existing_scheduler_and_duplicates(scans, tmp_path):
    from distributed import LocalCluster

    copy = tmp_path / "copy_of_apple.ply"
    copy.write_bytes(scans["good"][0].read_bytes())
    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None, scheduler_port=0) as cluster:
        opts = BuildOptions(scheduler=cluster.scheduler_address, points=POINTS)
        result = build_library([str(scans["good"][0]), str(copy)], tmp_path / "lib", opts)
    assert [r.status for r in result.records] == ["added", "duplicate"]
    assert result.cluster == cluster.scheduler_address and result.workers == 1


def test_unreachable_scheduler_is_one_error(scans, tmp_path, capsys):
    from arboretum_library.cli import main

    code = main(["library", "build", str(scans["good"][0]), "--library", str(tmp_path / "lib"),
                 "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2 and "cannot reach the Dask scheduler" in capsys.readouterr().err


def test_report_has_markdown_json_and_plots(built, tmp_path):
    from PIL import Image

    lib, result = built
    files = write_report(result, tmp_path / "rep")
    md = Path(files["markdown"]).read_text()
    assert md.count("| added |") == 4 and md.count("| failed |") == 3
    assert "![" in md and "curvature_lobes.png" in md
    data = json.loads(Path(files["json"]).read_text())
    assert (data["added"], data["failed"], data["scans"]) == (4, 3, 7)
    img = np.asarray(Image.open(files["curvature_lobes"]).convert("RGB"))
    assert img.shape == (480, 720, 3)
    # one coloured marker series per species: the apple colour (first series) is drawn
    assert np.all(img == [31, 119, 180], axis=2).sum() > 20
    bars = np.asarray(Image.open(files["scan_seconds"]).convert("RGB"))
    assert np.all(bars == [214, 39, 40], axis=2).sum() > 0  # failed scans in red


def test_helpers():
    assert species_for("/data/Cherry_tree_07.ply", None) == "cherry"
    assert species_for("/data/x.ply", None) == "unknown"
    assert species_for("/data/apple.ply", "Pine") == "pine"
    assert nice_ticks(0, 9.3) == [0, 2, 4, 6, 8, 10]
    with pytest.raises(Exception, match="workers"):
        BuildOptions(workers=0)


def test_expand_scans_folder(scans):
    files = expand_scans([str(scans["folder"][0])])
    assert len(files) == 7 and files == sorted(files)


def _build_cmd(scans: list[Path], lib: Path) -> list[str]:
    return [sys.executable, "-m", "arboretum_library.cli", "library", "build", *map(str, scans),
            "--library", str(lib), "--workers", "2", "--points", str(POINTS), "--json"]


def _complete_scans(lib: Path) -> int:
    with Library.open(lib, readonly=True) as L:
        per = {}
        for e in L.entries():
            per.setdefault(e.source_sha256, []).append(e.id)
        return sum(len(ids) == L.get(ids[0]).provenance.parameters[SCAN_EXAMPLES_KEY] for ids in per.values())


def _wait_for_a_scan(lib: Path, proc: subprocess.Popen, timeout: float = 120.0) -> int:
    """Wait until the build has stored every example of at least one scan."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            pytest.fail(f"build ended before it could be killed (exit {proc.returncode})")
        if (lib / "catalog.sqlite").exists():
            try:
                if (n := _complete_scans(lib)) > 0:
                    return n
            except Exception:  # the catalog is being created, or an example is being written
                pass
        time.sleep(0.1)
    pytest.fail("no example was stored in time")


@pytest.mark.parametrize("sig", [signal.SIGKILL, pytest.param(signal.SIGINT, marks=pytest.mark.slow)])
def test_killed_build_resumes_without_redoing(scans, tmp_path, sig):
    good = scans["good"]
    # Ctrl-C is caught between scans: with 6 scans a loaded machine once finished them all before the
    # signal came (exit 0), so that case gets 6 more
    more = synthetic_scans(tmp_path / "more", 2 if sig == signal.SIGKILL else 8, points=POINTS, first_seed=20)
    lib = tmp_path / "lib"
    env = {**os.environ, "OMP_WAIT_POLICY": "PASSIVE"}
    proc = subprocess.Popen(_build_cmd(good + more, lib), env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _wait_for_a_scan(lib, proc)
        if sig == signal.SIGKILL:
            os.killpg(proc.pid, signal.SIGKILL)  # the client and its workers, as a crash would
        else:
            proc.send_signal(signal.SIGINT)  # Ctrl-C in the client
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert code == (-signal.SIGKILL if sig == signal.SIGKILL else 130)
    with Library.open(lib, readonly=True) as L:
        done_before = {sha for sha, ids in _examples_per_source(lib).items()
                       if len(ids) == L.get(ids[0]).provenance.parameters[SCAN_EXAMPLES_KEY]}
    result = build_library([str(p) for p in good + more], lib, OPTS)
    n = len(good + more)
    assert result.count("failed") == 0 and result.count("added") + result.count("skipped") == n
    skipped = {r.sha256 for r in result.records if r.status == "skipped"}
    assert skipped == done_before and len(skipped) >= 1  # complete scans are not done again
    per_source = _examples_per_source(lib)
    assert len(per_source) == n
    with Library.open(lib, readonly=True) as L:
        for ids in per_source.values():
            assert len(ids) == L.get(ids[0]).provenance.parameters[SCAN_EXAMPLES_KEY]


def _worker_settings() -> dict:
    import dask

    return {"env": {k: v for k, v in os.environ.items() if k.startswith(("MALLOC_", "OMP_", "OPENBLAS_"))},
            "profile": dask.config.get("distributed.worker.profile.enabled")}


def test_local_workers_keep_glibc_malloc_defaults_and_no_profiler():
    """Any MALLOC_*_ variable turns off glibc's dynamic mmap threshold (decompose 1.25-2.5x slower)."""
    from arboretum_server.batch.build import _Cluster

    with _Cluster(BuildOptions(workers=1)) as (client, name, n):
        seen = list(client.run(_worker_settings).values())
    assert name == "LocalCluster" and n == 1 and len(seen) == 1
    env = seen[0]["env"]
    assert not [k for k in env if k.startswith("MALLOC_")]
    assert env["OMP_NUM_THREADS"] == "1" and env["OPENBLAS_NUM_THREADS"] == "1" and env["OMP_WAIT_POLICY"] == "PASSIVE"
    assert seen[0]["profile"] is False


def test_workers_start_without_a_trim_threshold_left_in_the_parent(monkeypatch):
    """A default LocalCluster's nanny leaves MALLOC_TRIM_THRESHOLD_=65536 in its process's environment."""
    from arboretum_server.batch.build import _Cluster

    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    with _Cluster(BuildOptions(workers=1)) as (client, _, _):
        env = next(iter(client.run(_worker_settings).values()))["env"]
        assert "MALLOC_TRIM_THRESHOLD_" not in os.environ
    assert "MALLOC_TRIM_THRESHOLD_" not in env and os.environ["MALLOC_TRIM_THRESHOLD_"] == "65536"


def test_a_scan_with_notes_carries_them_into_the_report(tmp_path):
    # a pole decomposes (its branches lie along it) but gets a note, which a library build of thousands
    # of scans dropped: the record, report.json, report.md and the command's text now carry it
    from arboretum_server.batch.build import BuildResult, ScanRecord, _store
    from arboretum_server.batch.cli import _text
    from arboretum_server.batch.plan import plan
    from arboretum_server.batch.report import as_dict
    from arboretum_server.batch.tasks import decompose_scan

    pole = tmp_path / "pole.xyz"
    write_points(pole, stubbed_pole(3000))  # a pole alone is refused (session 28): this one has three stubs
    out = decompose_scan(str(pole), file_sha256(pole), {"points": POINTS})
    assert out.error == "" and [n for n in out.notes if n.startswith("the cloud is nearly a straight line")]
    record = ScanRecord(str(pole), "unknown")
    with Library.open(tmp_path / "lib", create=True) as lib:
        _store(lib, record, out)
    assert record.status == "added" and record.notes == list(out.notes) and len(record.examples) >= 1
    result = BuildResult(str(tmp_path / "lib"), [record])
    files = write_report(result, tmp_path / "rep")
    data = json.loads(Path(files["json"]).read_text())
    assert data["records"][0]["notes"] == list(out.notes)
    assert "nearly a straight line" in Path(files["markdown"]).read_text()
    text = _text({**as_dict(result), "report": files})
    assert f"  note: {pole}: the cloud is nearly a straight line" in text
    # a rerun skips the scan and reports its notes again, read back from the library
    again = ScanRecord(str(pole), "unknown")
    with Library.open(tmp_path / "lib") as lib:
        assert plan(lib, [again]) == []
    assert again.status == "skipped" and again.notes == list(out.notes)
    files = write_report(BuildResult(str(tmp_path / "lib"), [again]), tmp_path / "rep2")
    row = [line for line in Path(files["markdown"]).read_text().splitlines() if "pole.xyz" in line]
    assert len(row) == 1 and "| unknown |" in row[0] and "nearly a straight line" in row[0]
    assert _cell("my|species\nname") == "my\\|species name"
