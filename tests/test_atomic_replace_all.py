"""``atomic.write_files_atomic`` replaces a set of files all or none, also when a rename fails partway
(``atomic.replace_all``; the OBJ writer's .mtl, textures and .obj go through it)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from arboretum_library.atomic import NotReplaced, write_files_atomic


def failing_second_replace(monkeypatch, exc: OSError) -> list[str]:
    """``os.replace`` failing with ``exc`` when it renames a new file onto 'b'; the renames seen."""
    real, seen = os.replace, []

    def replace(src, dst, *a, **k):
        seen.append(Path(dst).name)
        if Path(dst).name == "b" and Path(src).name.endswith(".tmp"):
            raise exc
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", replace)
    return seen


def test_a_failing_rename_leaves_every_file_as_it_was(monkeypatch, tmp_path):
    (tmp_path / "a").write_bytes(b"old a")
    (tmp_path / "b").write_bytes(b"old b")
    failing_second_replace(monkeypatch, OSError(errno.ENOSPC, "No space left on device"))
    with pytest.raises(NotReplaced) as e:
        write_files_atomic([(tmp_path / "a", b"new a"), (tmp_path / "b", b"new b"), (tmp_path / "c", b"new c")])
    assert e.value.filename == str(tmp_path / "b") and e.value.index == 1 and e.value.lost == ""
    assert e.value.errno == errno.ENOSPC and isinstance(e.value, OSError)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == {"a": b"old a", "b": b"old b"}


def test_a_destination_that_became_a_folder_is_refused_before_any_rename(tmp_path):
    (tmp_path / "a").write_bytes(b"old a")
    (tmp_path / "b").mkdir()
    with pytest.raises(NotReplaced, match="it is a folder now"):
        write_files_atomic([(tmp_path / "a", b"new a"), (tmp_path / "b", b"new b")])
    assert (tmp_path / "a").read_bytes() == b"old a" and (tmp_path / "b").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]


def test_success_replaces_every_file_and_leaves_nothing_hidden(tmp_path):
    (tmp_path / "a").write_bytes(b"old a")
    write_files_atomic([(tmp_path / "a", b"new a"), (tmp_path / "b", b"new b")])
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == {"a": b"new a", "b": b"new b"}
