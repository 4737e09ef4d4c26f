"""``arboretum library build`` run again over a library: pruned scans stay pruned, other options and edited
scans are reported (or rebuilt with --rebuild), a scheduler without workers is reported, subfolders are
mentioned (or read with --recursive), and a busy port 8787 brings no Dask warning."""

from __future__ import annotations

import dataclasses
import errno
import json
import logging
import shutil
import socket
import warnings
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.pointio import read_points, write_points
from arboretum_library.store import Library
from arboretum_server.batch import build as build_module
from arboretum_server.batch.build import BuildOptions, ScanRecord, build_library, expand_scans
from arboretum_server.batch.cli import _text
from arboretum_server.batch.plan import plan, scan_stem
from arboretum_server.batch.report import as_dict, write_report
from arboretum_server.batch.synthetic import synthetic_scans
from arboretum_server.batch.tasks import SCAN_EXAMPLES_KEY
from arboretum_server.batch.waiting import Waiting
from arboretum_server.decompose.examples import file_sha256

POINTS = 1500
OPTS = BuildOptions(workers=1, points=POINTS)


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> tuple[Path, list[Path]]:
    """A library of 2 synthetic scans (apple, cherry), built once; tests work on copies."""
    folder = tmp_path_factory.mktemp("rerun")
    scans = synthetic_scans(folder / "scans", 2, points=POINTS)
    lib = folder / "lib"
    result = build_library([str(p) for p in scans], lib, OPTS)
    assert result.count("added") == 2
    return lib, scans


def _copy(lib: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(lib, tmp_path / "lib"))


def _ids(lib: Path, sha: str) -> list[str]:
    with Library.open(lib, readonly=True) as L:
        return L.find_source(sha)


def test_deleted_example_stays_deleted(built, tmp_path):
    lib, scans = _copy(built[0], tmp_path), built[1]
    sha = file_sha256(scans[0])
    ids = _ids(lib, sha)
    with Library.open(lib) as L:
        L.delete(ids[1])  # the user prunes a bad example
    again = build_library([str(p) for p in scans], lib, OPTS)
    assert again.redone == 0 and again.count("skipped") == 2 and again.cluster == ""
    assert _ids(lib, sha) == [i for i in ids if i != ids[1]]
    rec = again.records[0]
    assert rec.examples == _ids(lib, sha)
    assert [n for n in rec.notes if n.startswith(f"1 of its {len(ids)} examples are no longer")]
    assert "--rebuild" in rec.notes[-1] and not again.records[1].notes


def test_quarantined_example_makes_its_scan_redone(built, tmp_path):
    # a torn folder found after a power loss is moved to quarantine/: that scan is done again
    lib, scans = _copy(built[0], tmp_path), built[1]
    sha = file_sha256(scans[0])
    ids = _ids(lib, sha)
    (lib / "quarantine").mkdir()
    shutil.copytree(lib / "examples" / ids[-1], lib / "quarantine" / f"{ids[-1]}-0badf00d")
    with Library.open(lib) as L:
        L.delete(ids[-1])
    again = build_library([str(p) for p in scans], lib, OPTS)
    assert again.redone == 1 and [r.status for r in again.records] == ["added", "skipped"]
    now = _ids(lib, sha)
    assert len(now) == len(ids) and again.records[0].examples == now  # all back, none doubled
    with Library.open(lib, readonly=True) as L:
        assert L.provenance(now[0]).parameters[SCAN_EXAMPLES_KEY] == len(now)
    assert "1 of them done again" in _text({**as_dict(again), "report": {}})
    with Library.open(lib) as L:
        L.delete(now[-1])  # pruned after the redo: the old quarantined folder no longer counts
    third = build_library([str(p) for p in scans], lib, OPTS)
    assert third.redone == 0 and third.count("skipped") == 2 and _ids(lib, sha) == now[:-1]


def test_rerun_with_other_options_reports_what_is_stored(built, tmp_path):
    lib, scans = _copy(built[0], tmp_path), built[1]
    before = {p: _ids(lib, file_sha256(p)) for p in scans}
    opts = BuildOptions(workers=1, points=POINTS, species="walnut", seed=3)
    again = build_library([str(p) for p in scans], lib, opts)
    assert again.count("skipped") == 2 and {p: _ids(lib, file_sha256(p)) for p in scans} == before
    assert [r.species for r in again.records] == ["apple", "cherry"]  # stored, not asked for
    note = again.records[0].notes[-1]
    assert "--species apple, --seed 0" in note and "--species walnut, --seed 3" in note and "--rebuild" in note
    files = write_report(again, tmp_path / "rep")
    data = json.loads(Path(files["json"]).read_text())
    assert data["records"][0]["species"] == "apple" and data["records"][0]["notes"][-1] == note
    row = next(line for line in Path(files["markdown"]).read_text().splitlines() if scans[0].name in line)
    assert "| apple | skipped |" in row and "--species walnut" in row
    assert f"  note: {scans[0]}: {note}" in _text({**data, "report": files})
    same = build_library([str(p) for p in scans], lib, OPTS)  # this run's options: no note
    assert [r.notes for r in same.records] == [[], []]


def test_rebuild_replaces_examples_with_this_runs_options(built, tmp_path, capsys):
    from arboretum_library.cli import main

    lib, scans = _copy(built[0], tmp_path), built[1]
    old = _ids(lib, file_sha256(scans[0]))
    other = _ids(lib, file_sha256(scans[1]))
    args = ["library", "build", str(scans[0]), "--library", str(lib), "--points", str(POINTS),
            "--seed", "3", "--workers", "1", "--rebuild", "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["redone"] == 1 and data["added"] == 1
    new = _ids(lib, file_sha256(scans[0]))
    assert new == data["records"][0]["examples"] and len(old) >= 1
    with Library.open(lib, readonly=True) as L:
        params = [L.provenance(i).parameters for i in new]
        assert {p["seed"] for p in params} == {3} and params[0][SCAN_EXAMPLES_KEY] == len(new)
        assert L.find_source(file_sha256(scans[1])) == other  # scans not given are left alone
    assert not set(new) & set(old)  # fresh ids: a session naming an old id never shows a new example


def test_edited_scan_notes_the_stale_examples(built, tmp_path):
    # the module's library, copied, with a copy of its first scan (it built its own library of that scan)
    lib = _copy(built[0], tmp_path)
    scan = Path(shutil.copy(built[1][0], tmp_path / built[1][0].name))
    old = _ids(lib, file_sha256(scan))
    assert old
    write_points(scan, read_points(scan).points[::2])  # the user thins the scan in place
    again = build_library([str(scan)], lib, OPTS)
    rec = again.records[0]
    assert rec.status == "added"
    stale = [n for n in rec.notes if "other contents" in n]
    assert len(stale) == 1 and f"holds {len(old)} examples of a file named {scan.name}" in stale[0]
    assert old[0] in stale[0] and "library delete" in stale[0]
    with Library.open(lib, readonly=True) as L:
        assert all(i in L for i in old)  # kept: the library knows only file names


def test_scheduler_without_workers_is_reported_and_waited_for(built, tmp_path):
    from distributed import LocalCluster

    scans = built[1]
    seen: list[str] = []
    with LocalCluster(n_workers=0, threads_per_worker=1, dashboard_address=None, scheduler_port=0) as cluster:
        opts = BuildOptions(scheduler=cluster.scheduler_address, points=POINTS, worker_timeout=1.5)
        with pytest.raises(InputError, match="no Dask worker joined in 1.5 s"):
            build_library([str(scans[0])], tmp_path / "lib", opts, lambda d, t, m="": seen.append(m))
        assert seen and "has 0 workers" in seen[-1] and cluster.scheduler_address in seen[-1]

        def start_one(done, total, message=""):
            seen.append(message)
            if "0 workers" in message and not cluster.workers:
                cluster.scale(1)  # a worker joins while the build waits

        seen.clear()
        result = build_library([str(scans[0])], tmp_path / "lib2", BuildOptions(
            scheduler=cluster.scheduler_address, points=POINTS), start_one)
    assert [r.status for r in result.records] == ["added"] and result.workers == 1
    waited = [k for k, m in enumerate(seen) if "0 workers" in m]
    assert waited and seen[waited[-1] + 1] == "building 0/1 scans" and seen[-1] == "building 1/1 scans"


def test_subfolders_are_mentioned_or_read_with_recursive(tmp_path):
    (tmp_path / "plot2" / "deep").mkdir(parents=True)
    rng = np.random.default_rng(0)
    for name in ("a.xyz", "plot2/b.xyz", "plot2/deep/c.xyz"):
        write_points(tmp_path / name, rng.normal(size=(50, 3)))
    (tmp_path / "plot2" / "QSM_cylinders.csv").write_text("start_x,start_y,start_z,axis_x,length,radius\n1,2,3,4,5,6\n")
    ignored: list = []
    assert expand_scans([str(tmp_path)], ignored) == [str(tmp_path / "a.xyz")]
    assert ignored == [(str(tmp_path / "plot2"), "a subfolder with 2 point-cloud files (pass it too, or use --recursive)")]
    ignored = []
    deep = expand_scans([str(tmp_path)], ignored, recursive=True)
    assert deep == [str(tmp_path / n) for n in ("a.xyz", "plot2/b.xyz", "plot2/deep/c.xyz")]
    assert [Path(p).name for p, _ in ignored] == ["QSM_cylinders.csv"]
    (tmp_path / "a.xyz").unlink()
    with pytest.raises(InputError, match=r"no point-cloud files, but 1 subfolder do .*plot2.*--recursive"):
        expand_scans([str(tmp_path)])


def test_busy_port_8787_brings_no_dask_warning():
    from arboretum_server.batch.build import _Cluster

    busy = socket.socket()
    try:
        busy.bind(("0.0.0.0", 8787))
        busy.listen()
    except OSError:  # another cluster holds it already: the same situation
        pass
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with _Cluster(BuildOptions(workers=1)) as (client, _, n):
                assert n == 1 and client.submit(sum, [1, 2]).result() == 3
    finally:
        busy.close()
    assert not [w for w in caught if "already in use" in str(w.message)]


def test_rebuild_that_cannot_store_keeps_the_old_examples(built, tmp_path, monkeypatch):
    lib, scans = _copy(built[0], tmp_path), built[1]
    sha = file_sha256(scans[0])
    old = _ids(lib, sha)

    def disk_full(self, examples, prefix="ex"):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Library, "add_new", disk_full)
    with pytest.raises(OSError, match="No space left"):
        build_library([str(scans[0])], lib, dataclasses.replace(OPTS, rebuild=True))
    assert _ids(lib, sha) == old and len(old) >= 2
    with Library.open(lib, readonly=True) as L:
        assert [L.get(i).id for i in old] == old


def test_rebuild_stopped_while_deleting_the_old_examples_loses_none(built, tmp_path, monkeypatch):
    lib, scans = _copy(built[0], tmp_path), built[1]
    sha = file_sha256(scans[0])
    old = _ids(lib, sha)
    real_delete, calls = Library.delete, []

    def delete(self, id_):
        calls.append(id_)
        if len(calls) == 2:
            raise KeyboardInterrupt  # Ctrl-C between two deletions
        real_delete(self, id_)

    monkeypatch.setattr(Library, "delete", delete)
    level = logging.getLogger("distributed").level
    try:
        with pytest.raises(KeyboardInterrupt):
            build_library([str(scans[0])], lib, dataclasses.replace(OPTS, rebuild=True))
    finally:
        logging.getLogger("distributed").setLevel(level)  # the build quietens Dask after a Ctrl-C
    monkeypatch.setattr(Library, "delete", real_delete)
    held = _ids(lib, sha)
    new = [i for i in held if i not in old]
    assert calls == old[:2] and [i for i in held if i in old] == old[1:] and len(new) == len(old)
    again = build_library([str(scans[0])], lib, OPTS)  # not "pruned by the user": says what happened
    rec = again.records[0]
    assert rec.status == "skipped" and again.redone == 0 and rec.examples == held
    assert rec.notes == [f"the library holds {len(held)} examples of it, not the {len(old)} it gives: a "
                         "--rebuild stopped while deleting the old ones; --rebuild again replaces them all"]
    third = build_library([str(scans[0])], lib, dataclasses.replace(OPTS, rebuild=True))
    now = _ids(lib, sha)
    assert third.redone == 1 and len(now) == len(old) and not set(now) & set(held)


def test_quarantined_id_is_matched_by_stem_and_never_reused(built, tmp_path):
    """A scan named 'apple tree (2).xyz': the plan's stem is the prefix ``add_new`` gives its ids, so a
    quarantined example is found; and a namesake stored afterwards does not take the quarantined id."""
    lib, scans = _copy(built[0], tmp_path), built[1]
    named = tmp_path / "apple tree (2).xyz"
    shutil.copyfile(scans[0], named)
    sha = file_sha256(named)
    with Library.open(lib, fsync=False) as L:
        examples = [L.get(i) for i in L.find_source(sha)]
        for e in examples:
            L.delete(e.id)
        ids = [e.id for e in L.add_new(examples, named.stem)]
        assert scan_stem(str(named)) == "apple-tree--2" and ids[0] == "apple-tree--2-0001"
        (lib / "quarantine").mkdir()
        shutil.copytree(lib / "examples" / ids[-1], lib / "quarantine" / f"{ids[-1]}-0badf00d")
        L.delete(ids[-1])  # a power loss tore it: the library moved it to quarantine/
        other = dataclasses.replace(examples[0], provenance=dataclasses.replace(
            examples[0].provenance, source_sha256="0" * 64))
        taken = L.add_new([other], named.stem)[0].id  # a namesake scan from another plot
        assert taken == f"apple-tree--2-{len(ids) + 1:04d}"
        rec = ScanRecord(str(named), "apple")
        assert plan(L, [rec], OPTS) == [rec] and rec.replace == ids[:-1]


def test_torn_example_with_its_row_makes_its_scan_redone(built, tmp_path, monkeypatch):
    lib, scans = _copy(built[0], tmp_path), built[1]
    sha = file_sha256(scans[0])
    old = _ids(lib, sha)
    (lib / "examples" / old[1] / "arrays.npz").write_bytes(b"")  # its data never reached the disk
    addresses = []

    class Recorded(Waiting):
        def __init__(self, client, address, *args):
            addresses.append(address)
            super().__init__(client, address, *args)

    monkeypatch.setattr(build_module, "Waiting", Recorded)
    again = build_library([str(p) for p in scans], lib, OPTS)
    assert again.redone == 1 and [r.status for r in again.records] == ["added", "skipped"]
    assert f"its example {old[1]} is damaged" in again.records[0].notes[-1]
    now = _ids(lib, sha)
    assert len(now) == len(old) and not set(now) & set(old) and again.records[0].examples == now
    with Library.open(lib, readonly=True) as L:
        assert [L.get(i).id for i in now] == now
    assert addresses == [None]  # a LocalCluster: no "start some: dask worker LocalCluster" hint


def test_local_cluster_without_workers_is_no_scheduler_to_start_workers_for(tmp_path, capsys):
    class NoWorkers:
        def nthreads(self):
            return {}

    seen: list[str] = []
    Waiting(NoWorkers(), None, OPTS, lambda d, t, m="": seen.append(m), lambda d, t: "").check()
    assert seen == ["waiting: the local cluster has 0 workers (a worker process is being restarted)"]
    with pytest.raises(InputError, match=r"^--worker-timeout applies only with --scheduler"):
        BuildOptions(worker_timeout=5)
    from arboretum_library.cli import main

    lib = tmp_path / "lib"
    assert main(["library", "build", str(tmp_path), "--library", str(lib), "--worker-timeout", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--worker-timeout applies only with --scheduler" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # refused before anything was made
