"""``arboretum library export/import`` (session 10): the ARCHIVE path is checked before any work and
never lands inside the library, a folder given as an archive is named as one, exports are
reproducible, the help lists every action, counts are singular when they are 1."""

from __future__ import annotations

import errno
import io
import json
import os
import tarfile
import time

import numpy as np
import pytest

from arboretum_library.archive import check_archive, export_archive
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.store import Library
from factories import make_example


def _lib(path, ids=("b-1", "a-1"), seed=0):
    with Library.open(path, create=True, fsync=False) as lib:
        for i, id_ in enumerate(ids):
            lib.add(make_example(np.random.default_rng(seed + i), id=id_, n_lobes=3))
    return path


@pytest.fixture
def lib_path(tmp_path):
    return _lib(tmp_path / "lib")


def _err_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def _files(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
            and not p.name.startswith("catalog.sqlite")}


@pytest.mark.parametrize("target, words", [
    ("examples/a-1/arrays.npz", "lies inside the library"),
    ("examples/a-1/meta.json", "lies inside the library"),
    ("backup.tar", "lies inside the library"),
    (".", "is a folder"),
])
def test_export_into_the_library_is_refused_and_changes_nothing(lib_path, capsys, target, words):
    before = _files(lib_path)
    assert main(["library", "export", str(lib_path), str(lib_path / target)]) == 2
    err = _err_line(capsys)
    assert words in err and "ARCHIVE" in err and ".tmp" not in err
    assert _files(lib_path) == before  # the example's arrays were replaced by the tar
    assert main(["library", "export", str(lib_path), str(lib_path.parent / "ok.tar"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["examples"] == 2  # and the library still exports


def test_export_api_refuses_a_path_inside_the_library(lib_path):
    before = _files(lib_path)
    with Library.open(lib_path, fsync=False) as lib, pytest.raises(InputError, match="inside the library"):
        export_archive(lib, lib_path / "examples" / "a-1" / "arrays.npz")
    assert _files(lib_path) == before


@pytest.mark.parametrize("make, words", [
    (lambda t: t / "missing" / "a.tar", "the folder"),
    (lambda t: (t / "adir").mkdir() or t / "adir", "is a folder"),
])
def test_export_target_is_checked_first_and_named(lib_path, tmp_path, capsys, monkeypatch, make, words):
    target = make(tmp_path)
    opened = []
    monkeypatch.setattr(Library, "open_reading", classmethod(lambda *a, **k: opened.append(1)))
    assert main(["library", "export", str(lib_path), str(target)]) == 2
    err = _err_line(capsys)
    assert f"ARCHIVE {target}" in err and words in err and ".tmp" not in err
    assert opened == []  # refused before the library was opened


def test_export_failing_while_writing_names_the_archive_not_the_temp_file(lib_path, tmp_path, monkeypatch):
    def full(*a, **k):  # what write() raises on a full disk: an OSError naming no file
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(tarfile.TarFile, "addfile", full)
    with Library.open(lib_path, fsync=False) as lib, pytest.raises(InputError) as info:
        export_archive(lib, tmp_path / "a.tar")
    assert str(info.value) == f"ARCHIVE {tmp_path / 'a.tar'}: cannot write it (No space left on device)"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib"]  # no temp file left


def test_import_of_a_folder_says_it_is_a_folder(lib_path, tmp_path, capsys):
    assert main(["library", "import", str(lib_path), str(tmp_path / "new")]) == 2
    err = _err_line(capsys)
    assert "is a folder, not an archive file" in err and "does not exist" not in err
    assert not (tmp_path / "new").exists()
    assert main(["library", "import", str(tmp_path / "nope.tar"), str(tmp_path / "new")]) == 2
    assert "does not exist" in _err_line(capsys)


def test_two_exports_are_byte_identical(lib_path, tmp_path, monkeypatch, capsys):
    assert main(["library", "export", str(lib_path), str(tmp_path / "1.tar")]) == 0
    real_time, real_gmtime = time.time, time.gmtime
    later = 86400 * 400.0  # another day and year
    monkeypatch.setattr(time, "time", lambda: real_time() + later)
    monkeypatch.setattr(time, "gmtime", lambda s=None: real_gmtime(real_time() + later if s is None else s))
    assert main(["library", "export", str(lib_path), str(tmp_path / "2.tar")]) == 0
    first = (tmp_path / "1.tar").read_bytes()
    assert first == (tmp_path / "2.tar").read_bytes()
    # the same examples in another library (imported from the archive): the same bytes again
    assert main(["library", "import", str(tmp_path / "1.tar"), str(tmp_path / "copy")]) == 0
    assert main(["library", "export", str(tmp_path / "copy"), str(tmp_path / "3.tar")]) == 0
    assert (tmp_path / "3.tar").read_bytes() == first
    capsys.readouterr()


def test_export_members_are_sorted_with_the_examples_own_times(lib_path, tmp_path):
    with Library.open(lib_path, fsync=False) as lib:
        export_archive(lib, tmp_path / "a.tar")
        created = {i: lib.entry(i).created for i in lib.ids()}
    with tarfile.open(tmp_path / "a.tar") as tf:
        members = tf.getmembers()
        manifest = json.loads(tf.extractfile("manifest.json").read())
    assert [m.name for m in members] == ["examples/a-1/meta.json", "examples/a-1/arrays.npz",
                                         "examples/b-1/meta.json", "examples/b-1/arrays.npz", "manifest.json"]
    stamp = {i: time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(m.mtime)) for m in members[:4]
             for i in [m.name.split("/")[1]]}
    assert stamp == created
    assert members[4].mtime == max(m.mtime for m in members[:4])
    assert set(manifest) == {"format", "schema", "examples"}  # no clock time
    assert all((m.uid, m.gid, m.uname, m.gname, m.mode) == (0, 0, "", "", 0o644) for m in members)


def test_an_archive_in_the_old_layout_still_imports(lib_path, tmp_path):
    """Archives before this session: a ``created`` field in the manifest, members in any order, the
    export's wall-clock time as every mtime."""
    with Library.open(lib_path, fsync=False) as lib:
        export_archive(lib, tmp_path / "new.tar")
    with tarfile.open(tmp_path / "new.tar") as tf:
        members = {m.name: tf.extractfile(m).read() for m in tf.getmembers()}
    manifest = json.loads(members.pop("manifest.json"))
    manifest = {"format": manifest["format"], "schema": manifest["schema"], "created": "2026-11-01T10:00:00Z",
                "examples": manifest["examples"][::-1]}
    with tarfile.open(tmp_path / "old.tar", "w", format=tarfile.PAX_FORMAT) as tf:
        for name, data in [*reversed(members.items()), ("manifest.json", json.dumps(manifest).encode())]:
            info = tarfile.TarInfo(name)
            info.size, info.mtime = len(data), 1_790_000_000
            tf.addfile(info, io.BytesIO(data))
    assert check_archive(tmp_path / "old.tar").ids == ("b-1", "a-1")
    with Library.open(tmp_path / "copy", create=True, fsync=False) as copy:
        report = copy.import_archive(tmp_path / "old.tar")
        assert report.added == ["b-1", "a-1"] and copy.ids() == ["a-1", "b-1"]


def test_library_help_lists_build_in_its_usage_block(capsys):
    with pytest.raises(SystemExit):
        main(["library", "--help"])
    out = capsys.readouterr().out
    usage = [line.strip() for line in out.split("Every subcommand")[0].splitlines() if line.startswith("    arboretum")]
    assert [u.split()[2] for u in usage] == ["info", "list", "search", "show", "delete", "export", "import", "build"]
    assert usage[-1] == "arboretum library build SCAN... --library LIB [options]"


def test_one_example_is_singular(tmp_path, capsys):
    lib = _lib(tmp_path / "one", ids=("a-1",))
    assert main(["library", "export", str(lib), str(tmp_path / "one.tar")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"exported 1 example to {tmp_path / 'one.tar'} (")
