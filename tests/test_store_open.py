"""Opening a library to read it (``Library.open_reading``), the write lock on its own (``store_lock``),
and how the commands that only read a library (``library list``, ``assemble``) open it and their inputs."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.errors import InputError, StoreError
from arboretum_library.store import LOCK_TIMEOUT_S, CatalogDamaged, Library, LibraryBusy
from arboretum_library.store_lock import WriteLock
from arboretum_server.assembly.cli import open_library, read_script
from factories import held_lock, make_example

N = 4


@pytest.fixture
def lib_path(tmp_path) -> Path:
    path = tmp_path / "lib"
    with Library.open(path, create=True, fsync=False) as lib:
        for i in range(N):
            lib.add(make_example(np.random.default_rng(i), id=f"ex-{i}", n_lobes=3))
    return path


def _garble_catalog(path: Path) -> None:
    with open(path / "catalog.sqlite", "r+b") as f:
        f.write(b"\x00garbage" * 64)


# -- Library.open_reading -----------------------------------------------------------------------------
def test_open_reading_a_sound_library_is_read_only_and_takes_no_lock(lib_path):
    with held_lock(lib_path), Library.open_reading(lib_path, lock_timeout=0.1) as lib:
        assert lib.readonly and lib.ids() == [f"ex-{i}" for i in range(N)]
        assert lib.recovered.catalog_problem == ""
        with pytest.raises(StoreError, match="opened read-only"):
            lib.delete("ex-0")


def test_open_reading_a_damaged_catalog_rebuilds_it_as_a_writer(lib_path):
    with Library.open(lib_path, readonly=True) as ro:
        before = ro.entries()
    _garble_catalog(lib_path)
    with pytest.raises(CatalogDamaged):
        Library.open(lib_path, readonly=True)
    with Library.open_reading(lib_path) as lib:
        assert not lib.readonly and lib.entries() == before
        assert lib.recovered.catalog_problem.startswith("is damaged")
        assert Path(lib.recovered.catalog_kept).name.startswith("catalog.sqlite.damaged-")
    with Library.open(lib_path, readonly=True) as ro:  # readers are fine again
        assert ro.entries() == before


def test_open_reading_waits_for_the_lock_as_told(lib_path):
    _garble_catalog(lib_path)
    told: list[str] = []
    with held_lock(lib_path):
        t = time.monotonic()
        with pytest.raises(LibraryBusy, match="being written by another process"):
            Library.open_reading(lib_path, lock_timeout=0.3, on_wait=told.append)
        assert 0.3 <= time.monotonic() - t < 2.0
    assert len(told) == 1 and told[0].startswith(f"waiting for the library {lib_path}")
    assert LOCK_TIMEOUT_S == 10.0


def test_open_reading_without_write_access_names_the_catalog_and_the_file(lib_path):
    _garble_catalog(lib_path)
    (lib_path / ".lock").unlink()
    (lib_path / ".lock").mkdir()  # opening the lock file fails, as on a library this process cannot write
    with pytest.raises(StoreError) as err:
        Library.open_reading(lib_path)
    message = str(err.value)
    assert message.startswith(f"the catalog {lib_path / 'catalog.sqlite'} is damaged")
    assert message.endswith(f"but this process cannot write the library (Is a directory: {lib_path / '.lock'})")
    assert not isinstance(err.value, CatalogDamaged)


# -- the write lock ------------------------------------------------------------------------------------
def test_the_write_lock_is_re_entrant_for_its_thread_and_excludes_other_threads(lib_path):
    lock = WriteLock(lib_path)
    outcome: list[str] = []

    def other_thread() -> None:
        try:
            with lock.hold(0.2, None):
                outcome.append("took it")
        except LibraryBusy:
            outcome.append("busy")

    with lock.hold(0.2, None):
        assert lock.held_here()
        t = threading.Thread(target=other_thread)
        t.start()
        t.join()
    assert outcome == ["busy"] and not lock.held_here()
    other_thread()
    assert outcome == ["busy", "took it"]


def test_locked_holds_the_lock_across_the_stores_own_writes(lib_path):
    with Library.open(lib_path, fsync=False, lock_timeout=0.2) as lib, lib.locked():
        lib.delete("ex-0")  # re-enters the lock this thread holds
        lib.add(make_example(np.random.default_rng(9), id="ex-9"))
        with Library.open(lib_path, readonly=True) as ro:  # a reader needs no lock
            assert "ex-9" in ro and "ex-0" not in ro
        with pytest.raises(LibraryBusy):
            Library.open(lib_path, fsync=False, lock_timeout=0.2)  # another writer waits, then gives up


# -- the commands that read a library -------------------------------------------------------------
def test_assemble_opens_a_damaged_library_by_rebuilding_it_or_names_why_not(lib_path):
    _garble_catalog(lib_path)
    with open_library(lib_path) as lib:
        assert lib.ids() == [f"ex-{i}" for i in range(N)] and lib.recovered.catalog_problem
    _garble_catalog(lib_path)
    (lib_path / ".lock").unlink()
    (lib_path / ".lock").mkdir()
    with pytest.raises(InputError) as err:
        open_library(lib_path)
    assert str(err.value).startswith(f"--library {lib_path}: cannot open the library (the catalog ")
    assert "this process cannot write the library" in str(err.value) and ".lock" in str(err.value)
    with pytest.raises(InputError, match=r"^--library: .*does not exist"):
        open_library(lib_path.parent / "none")


def test_assemble_names_a_missing_or_folder_script(tmp_path):
    with pytest.raises(InputError, match=f"^script {tmp_path / 'none.yaml'}: no such file$"):
        read_script(tmp_path / "none.yaml")
    with pytest.raises(InputError, match=f"^script {tmp_path}: is a folder, not a file$"):
        read_script(tmp_path)
    (tmp_path / "s.yaml").write_text("name: tree\nops:\n  - undo: {}\n")
    assert read_script(tmp_path / "s.yaml") == ("tree", [{"undo": {}}])


def test_grow_and_modules_read_an_assembly_against_a_library_whose_catalog_is_damaged(lib_path, tmp_path):
    """``world.load_structure`` (what ``grow`` and ``modules`` read) rebuilds a damaged catalog as the
    other readers do, and places the example it names."""
    from arboretum_library.assembly import Assembly, Placement
    from arboretum_library.codec import save_record
    from arboretum_server.assembly.world import load_structure

    record = tmp_path / "tree.npz"
    save_record(record, Assembly((Placement("a", "ex-1", np.eye(4)),)))
    (lib_path / "catalog.sqlite").write_bytes(b"not a database" * 100)
    hbl = load_structure(str(record), str(lib_path))
    with Library.open(lib_path, readonly=True) as lib:
        want = lib.get("ex-1").structure
        assert len(lib) == N
    assert len(hbl.branches) == len(want.branches) and len(hbl.lobes) == len(want.lobes) == 3
    np.testing.assert_allclose(hbl.branches[0].points, want.branches[0].points)


def test_provenance_is_read_from_meta_json_alone(lib_path):
    """``Library.provenance`` gives what ``get`` gives, without the arrays: a damaged arrays.npz does not
    stop it, a damaged meta.json or a missing id is one StoreError naming it."""
    folder = lib_path / "examples" / "ex-2"
    with Library.open(lib_path, readonly=True) as lib:
        want = lib.get("ex-2").provenance
        (folder / "arrays.npz").write_bytes(b"cut")
        assert lib.provenance("ex-2") == want
        with pytest.raises(StoreError, match="ex-2"):
            lib.get("ex-2")
        with pytest.raises(StoreError, match="no example 'ex-9'"):
            lib.provenance("ex-9")
        (folder / "meta.json").write_text('{"format": "something else"}')
        with pytest.raises(StoreError, match=r"ex-2 is damaged: .*not an Arboretum example"):
            lib.provenance("ex-2")
