"""The example store under other processes: a held write lock, racing imports, a damaged catalog, an
example replaced behind the server's back, and filters with very many tags."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import arboretum_library.store_write as store
from arboretum_library import protocol as P
from arboretum_library.cli import main
from arboretum_library.errors import StoreError
from arboretum_library.store import CatalogDamaged, Library, LibraryBusy
from factories import assert_examples_equal, held_lock, make_example

N = 6


@pytest.fixture
def lib_path(tmp_path) -> Path:
    path = tmp_path / "lib"
    with Library.open(path, create=True, fsync=False) as lib:
        for i in range(N):
            lib.add(make_example(np.random.default_rng(i), id=f"ex-{i}", n_lobes=7 if i % 3 else 2, curved=i % 2 == 0))
    return path


def _context(path: Path, tmp_path: Path, **options):
    from arboretum_server.service.context import Context
    from arboretum_server.service.dispatch import Dispatcher
    from arboretum_server.service.sessions import Sessions

    ctx = Context(Sessions(tmp_path / "state"), path, **options)
    return ctx, Dispatcher(ctx)


# -- 1. a held write lock ------------------------------------------------------------------------
def test_a_held_lock_makes_a_write_fail_after_its_timeout_not_hang(lib_path):
    with Library.open(lib_path, lock_timeout=0.3) as lib, held_lock(lib_path):
        t = time.monotonic()
        with pytest.raises(LibraryBusy, match=f"the library {lib_path} is being written by another process"):
            lib.delete("ex-0")
        assert 0.3 <= time.monotonic() - t < 2.0
        assert lib.ids() == [f"ex-{i}" for i in range(N)]  # reading needs no lock
        with pytest.raises(LibraryBusy):
            Library.open(lib_path, lock_timeout=0.2)  # opening for writing reconciles under the lock
    assert LibraryBusy("x").code == "busy"


def test_the_server_answers_busy_to_the_writer_and_serves_the_others(lib_path, tmp_path):
    ctx, d = _context(lib_path, tmp_path, lock_timeout=0.3)
    with held_lock(lib_path):
        reply = d.run(P.LibraryList())  # the first open takes the lock to reconcile
        assert isinstance(reply, P.Error) and reply.code == "busy"
    assert len(d.run(P.LibraryList()).entries) == N
    with held_lock(lib_path):
        t = time.monotonic()
        reply = d.run(P.LibraryDelete(id="ex-1"))
        assert isinstance(reply, P.Error) and reply.code == "busy" and "try again" in reply.message
        assert time.monotonic() - t < 2.0
        assert len(d.run(P.LibraryList()).entries) == N
        assert d.run(P.LibraryGet(id="ex-2")).example.id == "ex-2"
    assert isinstance(d.run(P.LibraryDelete(id="ex-1")), P.Ack)
    ctx.close()


def _cli(*argv: str) -> subprocess.Popen:
    code = "import sys; from arboretum_library.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.Popen([sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True)


def _wait_line(proc: subprocess.Popen, text: str, timeout: float = 20.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if text in line:
            return line
    raise AssertionError(f"no {text!r} on stderr")


def test_a_cli_writer_says_it_waits_and_stops_on_ctrl_c(lib_path):
    with held_lock(lib_path):
        proc = _cli("library", "delete", str(lib_path), "ex-0")
        line = _wait_line(proc, "waiting for the library")
        assert "another process is writing it (Ctrl-C to stop)" in line
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 130
        proc.stderr.close()
        proc = _cli("library", "delete", str(lib_path), "ex-0")
        _wait_line(proc, "waiting for the library")
    assert proc.wait(20) == 0  # went on once the lock was free
    proc.stderr.close()
    with Library.open(lib_path, readonly=True) as lib:
        assert "ex-0" not in lib and len(lib) == N - 1


# -- 2. ids picked under the lock ------------------------------------------------------------------
def test_concurrent_add_new_under_one_name_never_collide(lib_path, monkeypatch):
    slow_write = store.write_folder

    def write_folder(*args):
        time.sleep(0.02)  # widen the window between picking an id and storing it
        slow_write(*args)

    monkeypatch.setattr(store, "write_folder", write_folder)
    rng = np.random.default_rng(7)
    trees = {k: [make_example(rng, id="new") for _ in range(3)] for k in "AB"}
    got, start = {}, threading.Barrier(2)

    def run(k: str) -> None:
        with Library.open(lib_path, fsync=False) as lib:
            start.wait()
            got[k] = [e.id for e in lib.add_new(trees[k], "scan")]

    threads = [threading.Thread(target=run, args=(k,)) for k in "AB"]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(got["A"] + got["B"]) == [f"scan-{n:04d}" for n in range(1, 7)]
    with Library.open(lib_path, readonly=True) as lib:
        for k in "AB":
            for id_, ex in zip(got[k], trees[k], strict=True):
                assert_examples_equal(lib.get(id_), replace(ex, id=id_))
    assert list((lib_path / ".tmp").iterdir()) == []


def test_add_new_is_all_or_none(lib_path, monkeypatch):
    calls = []
    real = store.write_folder

    def fail_second(*args):
        calls.append(1)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        real(*args)

    rng = np.random.default_rng(8)
    with Library.open(lib_path, fsync=False) as lib:
        monkeypatch.setattr(store, "write_folder", fail_second)
        with pytest.raises(OSError):
            lib.add_new([make_example(rng, id="new") for _ in range(3)], "tree")
        monkeypatch.setattr(store, "write_folder", real)
        assert lib.ids() == [f"ex-{i}" for i in range(N)]
    assert sorted(os.listdir(lib_path / "examples")) == [f"ex-{i}" for i in range(N)]
    assert list((lib_path / ".tmp").iterdir()) == []


def test_a_crashed_group_add_is_rolled_back_by_the_next_writer(lib_path):
    (lib_path / ".tmp" / "journal-1-z.json").write_text(
        json.dumps({"op": "add_group", "id": "", "aside": None, "ids": ["ex-4", "ex-5", "ex-6"]}))
    with Library.open(lib_path) as lib:
        assert lib.ids() == [f"ex-{i}" for i in range(4)]
    assert sorted(os.listdir(lib_path / "examples")) == [f"ex-{i}" for i in range(4)]


# -- 3. a damaged catalog ------------------------------------------------------------------------
def _damage(path: Path, mode: str) -> bytes:
    """Damage LIB/catalog.sqlite; returns its bytes afterwards (what must be kept aside)."""
    db = path / "catalog.sqlite"
    if mode == "missing":
        for p in path.glob("catalog.sqlite*"):
            p.unlink()
        return b""
    if mode == "empty":
        os.truncate(db, 0)
    elif mode == "half":
        os.truncate(db, db.stat().st_size // 2)
    elif mode == "garbage":
        with open(db, "r+b") as f:
            f.write(b"\x00garbage" * 64)
    return db.read_bytes()


MODES = ("missing", "empty", "half", "garbage")


@pytest.mark.parametrize("mode", MODES)
def test_a_reader_names_the_damaged_catalog_and_a_writer_rebuilds_it(lib_path, mode):
    with Library.open(lib_path, readonly=True) as ro:
        before = ro.entries()
    damaged = _damage(lib_path, mode)
    with pytest.raises(CatalogDamaged, match=f"the catalog {lib_path / 'catalog.sqlite'} .*rebuilds it"):
        Library.open(lib_path, readonly=True)
    with Library.open(lib_path) as lib:
        assert lib.entries() == before
        assert lib.recovered.catalog_problem.startswith("is ")
        kept = lib.recovered.catalog_kept
        assert (mode == "missing") == (kept == "")
        if kept:
            assert Path(kept).read_bytes() == damaged and Path(kept).name.startswith("catalog.sqlite.damaged-")
    with Library.open(lib_path, readonly=True) as ro:
        assert ro.entries() == before


@pytest.mark.parametrize("mode", MODES)
def test_library_commands_rebuild_a_damaged_catalog_without_a_traceback(lib_path, mode, capsys):
    _damage(lib_path, mode)
    assert main(["library", "list", str(lib_path), "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["count"] == N
    assert f"the catalog {lib_path / 'catalog.sqlite'} is " in out.err and "rebuilt it" in out.err
    assert "Traceback" not in out.err
    assert main(["library", "show", str(lib_path), "ex-3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["id"] == "ex-3"


def test_a_server_on_a_damaged_catalog_rebuilds_it(lib_path, tmp_path):
    _damage(lib_path, "half")
    ctx, d = _context(lib_path, tmp_path)
    assert [e["id"] for e in d.run(P.LibraryList()).entries] == [f"ex-{i}" for i in range(N)]
    ctx.close()


def test_open_libraries_follow_a_catalog_another_process_rebuilt(lib_path):
    with Library.open(lib_path, readonly=True) as reader, Library.open(lib_path, fsync=False) as writer:
        assert len(reader) == N
        _damage(lib_path, "missing")
        with Library.open(lib_path, fsync=False) as other:  # rebuilds, then adds one
            other.add(make_example(np.random.default_rng(99), id="late"))
        assert "late" in reader and len(reader) == N + 1
        garbage = lib_path / "garbage.sqlite"
        garbage.write_bytes(b"\x00garbage" * 64)
        os.replace(garbage, lib_path / "catalog.sqlite")
        assert len(writer) == N + 1  # the writer rebuilt it under the lock
        writer.delete("late")
        assert len(reader) == N


# -- 4. an example replaced behind the server's back ----------------------------------------------
def test_the_server_sees_an_example_another_process_replaced_or_deleted(lib_path, tmp_path):
    ctx, d = _context(lib_path, tmp_path)
    first = d.run(P.LibraryGet(id="ex-3")).example
    assert ctx.example("ex-3") is ctx.example("ex-3")  # unchanged: served from the cache
    with Library.open(lib_path, fsync=False) as other:
        other.add(replace(first, tags=("replaced-by-cli",)), replace=True)
        other.delete("ex-4")
    assert d.run(P.LibraryGet(id="ex-3")).example.tags == ("replaced-by-cli",)
    reply = d.run(P.LibraryGet(id="ex-4"))
    assert isinstance(reply, P.Error) and "no example 'ex-4'" in reply.message
    ctx.close()


# -- 5. many tags --------------------------------------------------------------------------------
def test_filters_take_any_number_of_tags(lib_path, tmp_path):
    with Library.open(lib_path, readonly=True) as lib:
        assert lib.entries(tags=[f"t{i}" for i in range(1500)]) == []
        everyone = lib.entries()
        for want in (["dense"], ["sparse"], ["dense", "curved"], ["DENSE", "dense"], ["dense", "sparse"]):
            expect = [e for e in everyone if all(t.lower() in e.tags for t in want)]
            assert lib.entries(tags=want) == expect, want
        assert 0 < len(lib.entries(tags=["dense"])) < N and lib.entries(tags=["dense", "sparse"]) == []
    ctx, d = _context(lib_path, tmp_path)
    reply = d.run(P.LibraryList(tags=tuple(f"t{i}" for i in range(1001))))
    assert isinstance(reply, P.LibraryEntries) and reply.entries == ()
    ctx.close()


def test_a_busy_catalog_is_not_called_damaged(tmp_path):
    import sqlite3

    from arboretum_library import catalog

    err = sqlite3.OperationalError("database is locked")
    err.sqlite_errorname = "SQLITE_BUSY"
    out = catalog.damaged(tmp_path / "catalog.sqlite", err)
    assert type(out) is StoreError and "cannot be used right now" in str(out)


def test_a_reader_that_cannot_rebuild_says_so_in_one_line(lib_path, capsys):
    _damage(lib_path, "garbage")
    (lib_path / ".lock").unlink()
    (lib_path / ".lock").mkdir()  # opening the lock file for writing fails, as on a read-only library
    assert main(["library", "list", str(lib_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"the catalog {lib_path / 'catalog.sqlite'} is damaged" in err[0]
    assert "rebuilds it" in err[0] and "this process cannot write the library" in err[0]


@pytest.mark.parametrize("mode", ["skip", "rename"])
def test_three_processes_importing_one_archive_never_collide(tmp_path, mode):
    # apply_archive checked "id in lib" and picked new ids outside the write lock: one of two importers
    # stopped part-way with "already exists" (rename: 92 examples instead of 80; a reviewer's case)
    with Library.open(tmp_path / "src", create=True, fsync=False) as src:
        for i in range(60):
            src.add(make_example(np.random.default_rng(i), id=f"ex-{i}", n_lobes=3, n_points=300))
        src.export_archive(tmp_path / "a.tar")
    with Library.open(tmp_path / "dst", create=True, fsync=False) as dst:
        for i in range(60 if mode == "rename" else 0):
            dst.add(make_example(np.random.default_rng(100 + i), id=f"ex-{i}", n_lobes=3, n_points=300))
    code = (f"from arboretum_library.archive import apply_archive, check_archive\n"
            f"from arboretum_library.store import Library\n"
            f"from pathlib import Path\n"
            f"c = check_archive(Path({str(tmp_path / 'a.tar')!r}))\n"
            f"with Library.open({str(tmp_path / 'dst')!r}, fsync=False) as lib:\n"
            f"    r = apply_archive(lib, c, {mode!r})\n"
            f"print(len(r.added), len(r.skipped), len(r.renamed))\n")
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(3)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], [o[1][-300:] for o in outs]
    counts = sorted(tuple(int(v) for v in o[0].split()) for o in outs)
    with Library.open(tmp_path / "dst", readonly=True) as dst:
        if mode == "skip":
            assert sum(c[0] for c in counts) == 60 and sum(c[1] for c in counts) == 120 and len(dst) == 60
        else:
            assert counts == [(0, 0, 60)] * 3 and len(dst) == 240
