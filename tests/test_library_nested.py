"""A new library inside another library's folder is refused: ``library import a.tar L/examples/new``
made one there, which the outer library would then meet among its example folders."""

from __future__ import annotations

import pytest

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.folders import enclosing_library
from arboretum_library.store import Library


def test_a_library_is_not_created_inside_another(tmp_path):
    outer = tmp_path / "outer"
    Library.open(outer, create=True)
    before = sorted(p.relative_to(outer) for p in outer.rglob("*"))
    for inner in (outer / "examples" / "new", outer / "sub" / "deeper"):
        with pytest.raises(InputError, match=r"lies inside the library .*outer"):
            Library.open(inner, create=True)
    assert sorted(p.relative_to(outer) for p in outer.rglob("*")) == before  # no folder made
    assert enclosing_library(outer / "examples" / "x") == outer.resolve()
    assert enclosing_library(outer) is None and enclosing_library(tmp_path / "beside") is None
    Library.open(tmp_path / "beside", create=True)  # a sibling is fine


def test_library_import_into_a_folder_of_another_library_is_one_line(tmp_path, capsys):
    outer = tmp_path / "outer"
    Library.open(outer, create=True)
    archive = tmp_path / "a.tar"
    assert main(["library", "export", str(outer), str(archive)]) == 0
    code = main(["library", "import", str(archive), str(outer / "examples" / "new")])
    err = capsys.readouterr().err
    assert code == 2 and "lies inside the library" in err and "Traceback" not in err
    assert not (outer / "examples" / "new").exists()


def test_another_tools_library_json_above_is_no_library(tmp_path):
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "library.json").write_text('{"name": "my-firmware", "version": "1.0.0"}')  # PlatformIO
    assert enclosing_library(proj / "trees" / "lib") is None
    Library.open(proj / "trees" / "lib", create=True)
    assert (proj / "trees" / "lib" / "library.json").is_file()


def test_a_deeply_nested_or_huge_library_json_above_is_no_library(tmp_path):
    for i, text in enumerate(["[" * 100_000, '{"format": "arboretum-library"' + " " * 70_000 + "}"]):
        proj = tmp_path / f"p{i}"
        proj.mkdir()
        (proj / "library.json").write_text(text)
        assert enclosing_library(proj / "lib") is None  # a RecursionError before; the second too long
