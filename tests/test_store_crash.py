"""Crash consistency: a writer killed at random moments never leaves a broken or half-listed library.

Run as a script (``python test_store_crash.py LIB``) this file is the writer: it adds examples in a loop
with fsync on (and re-adds every third one with replace=True) until it is killed.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def expected(i: int):
    from factories import make_example

    return make_example(np.random.default_rng(i), id=f"ex-{i:05d}", n_lobes=i % 8, curved=bool(i % 2))


def _writer(path: str) -> None:
    from arboretum_library.store import Library

    lib = Library.open(path, create=True, fsync=True)
    i = max((int(x[3:]) for x in lib.ids()), default=-1) + 1
    print("ready", flush=True)
    while True:
        lib.add(expected(i))
        if i % 3 == 0:
            lib.add(expected(i), replace=True)
        i += 1


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    _writer(sys.argv[1])
    raise SystemExit(0)

import pytest  # noqa: E402

from arboretum_library.store import Library  # noqa: E402
from factories import assert_examples_equal, make_example, run_then_kill  # noqa: E402


def _check_whole(root: Path) -> int:
    """Reopen as a writer; every listed example loads and equals what was written. Returns the count."""
    with Library.open(root) as lib:
        ids = lib.ids()
        assert list((root / ".tmp").iterdir()) == []
        assert not (root / "quarantine").exists() or list((root / "quarantine").iterdir()) == []
        assert sorted(p.name for p in (root / "examples").iterdir()) == ids
        for id_ in ids:
            assert_examples_equal(lib.get(id_), expected(int(id_[3:])))
        assert ids == [f"ex-{i:05d}" for i in range(len(ids))]
        return len(ids)


def test_sigkilled_writer_leaves_a_whole_library(tmp_path):
    root = tmp_path / "lib"
    delays = np.random.default_rng(7).uniform(0.05, 0.5, 5)
    counts = [0]
    for delay in delays:
        run_then_kill(__file__, root, delay)
        counts.append(_check_whole(root))
        assert counts[-1] >= counts[-2], counts
    assert counts[-1] >= 5, counts


# -- deterministic crash points, reconciled on open ---------------------------------------------

@pytest.fixture
def lib_path(tmp_path):
    path = tmp_path / "lib"
    with Library.open(path, create=True) as lib:
        lib.add_many([make_example(np.random.default_rng(i), id=f"ex-{i}") for i in range(3)])
    return path


def test_orphan_folder_is_reindexed_and_broken_one_quarantined(lib_path, tmp_path):
    with Library.open(tmp_path / "other", create=True) as other:
        extra = make_example(np.random.default_rng(10), id="orphan", n_lobes=7)
        other.add(extra)
    os.rename(tmp_path / "other" / "examples" / "orphan", lib_path / "examples" / "orphan")
    broken = lib_path / "examples" / "broken"
    broken.mkdir()
    (broken / "meta.json").write_text("{")
    with Library.open(lib_path, readonly=True) as ro:
        assert ro.ids() == ["ex-0", "ex-1", "ex-2"]  # readers never reconcile
    with Library.open(lib_path) as lib:
        assert lib.recovered.reindexed == ["orphan"]
        assert [q.split("-")[0] for q in lib.recovered.quarantined] == ["broken"]
        assert lib.ids() == ["ex-0", "ex-1", "ex-2", "orphan"]
        assert lib.entry("orphan").tags == ("dense", "straight")
        assert_examples_equal(lib.get("orphan"), extra)
    assert (lib_path / "quarantine").is_dir() and not broken.exists()


def test_row_without_folder_dropped_and_tmp_cleaned(lib_path):
    import shutil

    shutil.rmtree(lib_path / "examples" / "ex-1")
    (lib_path / ".tmp" / "stage-123-abc").mkdir()
    (lib_path / ".tmp" / "stage-123-abc" / "arrays.npz").write_bytes(b"half")
    with Library.open(lib_path) as lib:
        assert lib.recovered.dropped == ["ex-1"] and lib.recovered.cleaned == 1
        assert lib.ids() == ["ex-0", "ex-2"]
        assert list((lib_path / ".tmp").iterdir()) == []


def test_replace_crashed_between_renames_restores_the_old_example(lib_path):
    with Library.open(lib_path, readonly=True) as ro:
        old = ro.get("ex-2")
    tmp = lib_path / ".tmp"
    os.rename(lib_path / "examples" / "ex-2", tmp / "aside-1-x")
    (tmp / "journal-1-x.json").write_text(json.dumps({"op": "replace", "id": "ex-2", "aside": "aside-1-x"}))
    with Library.open(lib_path) as lib:
        assert lib.ids() == ["ex-0", "ex-1", "ex-2"]
        assert_examples_equal(lib.get("ex-2"), old)
        assert list(tmp.iterdir()) == []


def test_delete_crashed_before_its_folder_went_is_completed(lib_path):
    (lib_path / ".tmp" / "journal-1-y.json").write_text(json.dumps({"op": "delete", "id": "ex-0", "aside": None}))
    with Library.open(lib_path) as lib:
        assert lib.ids() == ["ex-1", "ex-2"]
        assert not (lib_path / "examples" / "ex-0").exists()


def test_lost_catalog_is_rebuilt_from_the_folders(lib_path):
    with Library.open(lib_path, readonly=True) as ro:
        before = [ro.entry(i) for i in ro.ids()]
    for p in lib_path.glob("catalog.sqlite*"):
        p.unlink()
    with Library.open(lib_path) as lib:
        assert lib.recovered.reindexed == ["ex-0", "ex-1", "ex-2"]
        assert [lib.entry(i) for i in lib.ids()] == before
