"""Output paths (review s10, finding 5): two outputs that are one file through a linked folder are
refused like two outputs with one name, and ``assemble --out`` writes only .npz records."""

from __future__ import annotations

import os

import pytest

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output, same_file
from factories import make_library


@pytest.fixture
def alias(tmp_path):
    """tmp_path/real (a folder) and tmp_path/alias, a link to it."""
    (tmp_path / "real").mkdir()
    (tmp_path / "alias").symlink_to(tmp_path / "real")
    return tmp_path / "alias"


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return make_library(tmp_path_factory.mktemp("review_outputs") / "lib", 1)


def test_new_files_through_a_linked_folder_are_the_same_file(tmp_path, alias):
    real = tmp_path / "real"
    assert same_file(real / "t.glb", alias / "t.glb")
    assert same_file(alias / "t.glb", real / "t.glb")
    (real / "deep").mkdir()
    (tmp_path / "deep").symlink_to(real / "deep")  # '..' after a link is the parent of its target
    assert same_file(tmp_path / "deep" / ".." / "t.glb", real / "t.glb")
    assert not same_file(tmp_path / "deep" / ".." / "t.glb", tmp_path / "t.glb")
    assert not same_file(real / "t.glb", alias / "u.glb")
    (real / "t.glb").write_bytes(b"x")  # one exists, the other does not: two files
    assert not same_file(real / "t.glb", alias / "v.glb")


def test_a_link_as_the_file_itself_is_its_own_entry(tmp_path):
    # a write renames a temporary file over the link, replacing the link and not its target
    (tmp_path / "dangling.glb").symlink_to(tmp_path / "target.glb")
    assert not same_file(tmp_path / "dangling.glb", tmp_path / "target.glb")
    assert same_file(tmp_path / "dangling.glb", tmp_path / "dangling.glb")


def test_an_output_named_again_through_the_link_is_refused(tmp_path, alias, monkeypatch):
    monkeypatch.chdir(tmp_path / "real")
    with pytest.raises(InputError) as info:  # review case: export to alias/sess.glb with --out sess.glb
        check_output(alias / "sess.glb", "out", outputs=["sess.glb"])
    assert str(info.value) == f"out {alias / 'sess.glb'}: is also another output sess.glb; choose another name"
    assert check_output(alias / "other.glb", "out", outputs=["sess.glb"]) == alias / "other.glb"


def test_two_exports_to_one_file_through_a_link_write_nothing(tmp_path, alias, lib, capsys):
    script = tmp_path / "s.yaml"
    script.write_text(f"- add: {{example: ex-0, as: a}}\n- export: {{out: {tmp_path}/real/same.glb}}\n"
                      f"- export: {{out: {alias}/same.glb, options: {{density: 0.3}}}}\n")
    code = main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "o.npz")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert (f"operation 3 (export): out {alias}/same.glb: is also another output {tmp_path}/real/same.glb"
            in err)
    assert os.listdir(tmp_path / "real") == [] and not (tmp_path / "o.npz").exists()


@pytest.mark.parametrize("name", ["sess.glb", "session", "s.NPZ.txt"])
def test_assemble_out_must_be_an_npz_record(tmp_path, lib, capsys, name):
    script = tmp_path / "s.yaml"
    script.write_text("- add: {example: ex-0, as: a}\n")
    code = main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / name)])
    err = capsys.readouterr().err
    suffix = os.path.splitext(name)[1] or "a file without suffix"
    assert (code, err) == (2, f"arboretum assemble: error: --out {tmp_path / name}: writes .npz files, not {suffix}\n")
    assert sorted(os.listdir(tmp_path)) == ["s.yaml"]


def test_assemble_out_in_upper_case_npz_is_taken(tmp_path, lib, capsys):
    script = tmp_path / "s.yaml"
    script.write_text("- add: {example: ex-0, as: a}\n")
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "S.NPZ")]) == 0
    assert (tmp_path / "S.NPZ").read_bytes()[:2] == b"PK"
    capsys.readouterr()
