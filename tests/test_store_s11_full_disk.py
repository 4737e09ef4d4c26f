"""A library on a full disk (helper-82's hunt, findings 3 and 4): creating one leaves nothing that blocks
a retry, a failed run is never half visible and is one line on the CLI and the wire, nothing stored
before is lost.

The disk fills up from the k-th file write on: every write of an example file or a journal from then
on creates its file and fails in write() with ENOSPC naming no file, as a real full disk does.
"""

from __future__ import annotations

import errno
import os
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

import arboretum_library.folders as folders
import arboretum_library.recovery as recovery
from arboretum_library import catalog
from arboretum_library.cli import main
from arboretum_library.errors import InputError, StoreError
from arboretum_library.store import Library
from factories import assert_examples_equal, make_example

N = 4
ENOSPC = os.strerror(errno.ENOSPC)


def _old(i: int):
    return make_example(np.random.default_rng(i), id=f"ex-{i}", n_lobes=3 + i)


@pytest.fixture
def lib_path(tmp_path) -> Path:
    path = tmp_path / "lib"
    with Library.open(path, create=True, fsync=False) as lib:
        for i in range(N):
            lib.add(_old(i))
    return path


def disk_full_from(monkeypatch, k: int) -> list[Path]:
    """Every example-file and journal write from the ``k``-th (1-based) on fails with ENOSPC; returns
    the paths tried, in order."""
    tried: list[Path] = []
    real = folders.write_bytes

    def write_bytes(path: Path, data: bytes, durable: bool) -> None:
        tried.append(Path(path))
        if len(tried) < k:
            return real(path, data, durable)
        open(path, "xb").close()  # open() worked, write() found the disk full
        raise OSError(errno.ENOSPC, ENOSPC)

    monkeypatch.setattr(folders, "write_bytes", write_bytes)
    monkeypatch.setattr(recovery, "write_bytes", write_bytes)
    return tried


def _trees(seed: int, n: int = 3) -> list:
    rng = np.random.default_rng(seed)
    return [make_example(rng, id="new", n_lobes=2 + i) for i in range(n)]


def _assert_as_before(path: Path) -> None:
    """The library holds exactly the N old examples, whole, in catalog and folders; .tmp/ is empty."""
    with Library.open(path, readonly=True) as ro:
        assert ro.ids() == [f"ex-{i}" for i in range(N)]
    with Library.open(path, fsync=False) as lib:  # a writing open reconciles: nothing to do
        assert lib.ids() == [f"ex-{i}" for i in range(N)]
        assert lib.recovered.reindexed == [] and lib.recovered.dropped == []
        for i in range(N):
            assert_examples_equal(lib.get(f"ex-{i}"), _old(i))
    assert sorted(os.listdir(path / "examples")) == [f"ex-{i}" for i in range(N)]
    assert list((path / ".tmp").iterdir()) == []


# -- finding 3: creating a library ----------------------------------------------------------------------
def _fail_write_text(monkeypatch) -> None:
    def write_text(self, *args, **kwargs):
        open(self, "xb").close()
        raise OSError(errno.ENOSPC, ENOSPC)

    monkeypatch.setattr(Path, "write_text", write_text)


@pytest.mark.parametrize("made_by_user", [False, True])
def test_a_library_not_created_on_a_full_disk_leaves_nothing_and_a_retry_creates_it(tmp_path, monkeypatch,
                                                                                     made_by_user):
    path = tmp_path / "new"
    if made_by_user:
        path.mkdir()
    with monkeypatch.context() as m:
        _fail_write_text(m)
        with pytest.raises(StoreError) as err:
            Library.open(path, create=True)
    assert str(err.value) == f"library {path}: no space left on device (ENOSPC); it was not created"
    assert isinstance(err.value, StoreError) and err.value.errno == errno.ENOSPC
    assert (sorted(os.listdir(path)) == []) if made_by_user else not path.exists()  # no .library.json.PID.tmp
    with Library.open(path, create=True) as lib:  # space freed: the retry creates it
        lib.add(_old(0))
        assert lib.ids() == ["ex-0"]


def test_ctrl_c_while_creating_a_library_leaves_nothing(tmp_path, monkeypatch):
    def interrupted(self, *args, **kwargs):
        open(self, "xb").close()
        raise KeyboardInterrupt

    path = tmp_path / "made"
    path.mkdir()
    with monkeypatch.context() as m:
        m.setattr(Path, "write_text", interrupted)
        with pytest.raises(KeyboardInterrupt):
            Library.open(path, create=True)
    assert os.listdir(path) == []
    Library.open(path, create=True).close()
    assert (path / "library.json").is_file()


def test_a_marker_temp_left_by_a_dead_process_is_ignored_and_removed(tmp_path):
    path = tmp_path / "new"
    path.mkdir()
    dead = path / ".library.json.4194399.tmp"  # above Linux's largest pid (2**22): no such process
    alive = path / f".library.json.{os.getppid()}.tmp"  # another creation under way: left to it
    for p in (dead, alive):
        p.write_text("")
    with Library.open(path, create=True) as lib:
        assert lib.ids() == []
    assert not dead.exists() and alive.exists()
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="is not empty"):  # a folder with anything else is still refused
        Library.open(other, create=True)


def test_the_cli_creating_a_library_on_a_full_disk_prints_one_line_and_a_retry_works(tmp_path, monkeypatch,
                                                                                        capsys, lib_path):
    with Library.open(lib_path, readonly=True) as lib:
        lib.export_archive(tmp_path / "a.tar")
    target = tmp_path / "made"
    target.mkdir()
    with monkeypatch.context() as m:
        _fail_write_text(m)
        assert main(["library", "import", str(tmp_path / "a.tar"), str(target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"arboretum library: error: library {target}: no space left on device (ENOSPC); it was not created"]
    assert os.listdir(target) == []
    assert main(["library", "import", str(tmp_path / "a.tar"), str(target)]) == 0
    with Library.open(target, readonly=True) as lib:
        assert lib.ids() == [f"ex-{i}" for i in range(N)]


# -- finding 4: storing a run ---------------------------------------------------------------------------
@pytest.mark.parametrize("k", range(1, 8))  # 1: the group journal, then each example's two files
def test_a_run_failing_on_a_full_disk_stores_nothing_and_says_so_in_one_line(lib_path, monkeypatch, k):
    with Library.open(lib_path, fsync=False) as lib:
        with monkeypatch.context() as m:
            tried = disk_full_from(m, k)
            with pytest.raises(StoreError) as err:
                lib.add_new(_trees(k), "tree")
        assert str(err.value) == f"library {lib_path}: no space left on device (ENOSPC); nothing was stored"
        assert isinstance(err.value, OSError) and err.value.errno == errno.ENOSPC  # still an OSError
        assert len(tried) == k and tried[0].name.startswith("journal-")
        assert lib.ids() == [f"ex-{i}" for i in range(N)]
        assert [e.id for e in lib.add_new(_trees(9), "tree")] == ["tree-0001", "tree-0002", "tree-0003"]
        lib.delete("tree-0001"), lib.delete("tree-0002"), lib.delete("tree-0003")
    _assert_as_before(lib_path)


@pytest.mark.parametrize("k", [1, 4, 7])
def test_ctrl_c_while_a_run_is_stored_takes_it_back(lib_path, monkeypatch, k):
    real, calls = folders.write_bytes, []

    def write_bytes(path, data, durable):
        calls.append(path)
        if len(calls) == k:
            raise KeyboardInterrupt
        real(path, data, durable)

    with Library.open(lib_path, fsync=False) as lib, monkeypatch.context() as m:
        m.setattr(folders, "write_bytes", write_bytes)
        m.setattr(recovery, "write_bytes", write_bytes)
        with pytest.raises(KeyboardInterrupt):
            lib.add_new(_trees(k), "tree")
    _assert_as_before(lib_path)


def test_a_reader_never_sees_part_of_a_run_whose_roll_back_needs_a_full_disk(lib_path, monkeypatch):
    # the disk fills while the second example is written: before, the roll-back of the first one had to
    # write a journal, failed, and readers listed it until a later write took it back
    with Library.open(lib_path, fsync=False) as lib, monkeypatch.context() as m:
        disk_full_from(m, 5)
        with pytest.raises(StoreError, match="nothing was stored$"):
            lib.add_new(_trees(5), "tree")
        with Library.open(lib_path, readonly=True) as ro:
            assert ro.ids() == [f"ex-{i}" for i in range(N)] and len(ro.entries()) == N
    _assert_as_before(lib_path)


def test_a_full_catalog_at_the_commit_stores_nothing(lib_path, monkeypatch):
    def full(con, entry):
        err = sqlite3.OperationalError("database or disk is full")
        err.sqlite_errorname = "SQLITE_FULL"
        raise err

    with Library.open(lib_path, fsync=False) as lib:
        with monkeypatch.context() as m:
            m.setattr(catalog, "upsert", full)
            with pytest.raises(StoreError) as err:
                lib.add_new(_trees(3), "tree")
        assert str(err.value) == (f"library {lib_path}: no space left on device (ENOSPC, {lib_path / 'catalog.sqlite'}); "
                                  "nothing was stored")
        assert [e.id for e in lib.add_new(_trees(4, 1), "t")] == ["t-0001"]  # the catalog's transaction ended
        lib.delete("t-0001")
    _assert_as_before(lib_path)


def test_a_roll_back_that_cannot_finish_says_the_next_write_does_and_readers_see_nothing(lib_path, monkeypatch):
    real_rename, calls = os.rename, []

    def rename(src, dst):
        calls.append(dst)
        if len(calls) == 3:  # two examples are in examples/ already
            raise OSError(errno.ENOSPC, ENOSPC)
        real_rename(src, dst)

    def rmtree(path, *args, **kwargs):
        raise OSError(errno.EIO, os.strerror(errno.EIO), str(path))

    with Library.open(lib_path, fsync=False) as lib:
        with monkeypatch.context() as m:
            m.setattr(os, "rename", rename)
            m.setattr(shutil, "rmtree", rmtree)
            with pytest.raises(StoreError) as err:
                lib.add_new(_trees(6), "tree")
        assert str(err.value) == (f"library {lib_path}: no space left on device (ENOSPC); "
                                  "nothing was stored (the next write to the library removes what is left)")
        assert sorted(os.listdir(lib_path / "examples"))[-2:] == ["tree-0001", "tree-0002"]  # left on disk...
        with Library.open(lib_path, readonly=True) as ro:
            assert ro.ids() == [f"ex-{i}" for i in range(N)]  # ...but no reader lists them
        assert lib.ids() == [f"ex-{i}" for i in range(N)]
        lib.delete("ex-0")  # the next write takes them back first
        assert sorted(os.listdir(lib_path / "examples")) == [f"ex-{i}" for i in range(1, N)]
        assert list((lib_path / ".tmp").iterdir()) == []


def test_a_single_add_or_delete_on_a_full_disk_is_one_line_and_changes_nothing(lib_path, monkeypatch):
    with Library.open(lib_path, fsync=False) as lib:
        for k in (1, 2, 3):  # arrays, meta.json, the add's journal
            with monkeypatch.context() as m:
                disk_full_from(m, k)
                with pytest.raises(StoreError) as err:
                    lib.add(make_example(np.random.default_rng(k), id="one"))
            assert str(err.value) == f"library {lib_path}: no space left on device (ENOSPC); example 'one' was not stored"
        with monkeypatch.context() as m:
            disk_full_from(m, 1)
            with pytest.raises(StoreError) as err:
                lib.delete("ex-1")
        assert str(err.value) == f"library {lib_path}: no space left on device (ENOSPC); example 'ex-1' was not deleted"
    _assert_as_before(lib_path)


def test_cli_main_turns_a_disk_error_naming_no_file_into_one_line(lib_path, monkeypatch, capsys):
    def full(self):  # what a flush() or close() on a full disk raises, outside the store's own writes
        raise OSError(errno.ENOSPC, ENOSPC)

    monkeypatch.setattr(Library, "info", full)
    assert main(["library", "info", str(lib_path)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [f"arboretum library: error: {ENOSPC}"]

    def bug(self):
        raise OSError(errno.EBADF, os.strerror(errno.EBADF))

    monkeypatch.setattr(Library, "info", bug)
    with pytest.raises(OSError, match="Bad file descriptor"):  # any other OSError naming no file is a bug
        main(["library", "info", str(lib_path)])
