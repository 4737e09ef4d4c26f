"""``outputs.check_output``: output paths refused before any work, naming the option and the path."""

from __future__ import annotations

import os

import pytest

from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output, same_file


def test_a_good_path_passes_and_comes_back_as_a_path(tmp_path):
    (tmp_path / "in.npz").write_bytes(b"x")
    out = check_output(tmp_path / "tree.glb", inputs=[tmp_path / "in.npz", None], suffixes=(".glb", ".gltf"))
    assert out == tmp_path / "tree.glb"


@pytest.mark.parametrize("name, kwargs, words", [
    ("in.npz", {"inputs": ["in.npz"]}, r"--out .*in.npz: is the input .*in.npz; choose another name"),
    ("sub", {}, r"--out .*sub: is a folder"),
    ("missing/x.glb", {}, r"the folder .*missing does not exist"),
    ("in.npz/x.glb", {}, r"in.npz is a file, not a folder"),
    ("x.jpg", {"suffixes": [".png"]}, r"writes \.png files, not \.jpg"),
    ("m.ply", {"outputs": ["m.ply"]}, r"is also another output .*m.ply"),
])
def test_bad_output_paths_are_one_clear_error(tmp_path, name, kwargs, words):
    (tmp_path / "in.npz").write_bytes(b"x")
    (tmp_path / "sub").mkdir()
    kwargs = {k: [tmp_path / v for v in vs] if k != "suffixes" else vs for k, vs in kwargs.items()}
    with pytest.raises(InputError, match=words):
        check_output(tmp_path / name, **kwargs)


def test_the_same_file_through_a_link_or_a_relative_path(tmp_path, monkeypatch):
    (tmp_path / "a.xyz").write_text("1 2 3\n")
    os.link(tmp_path / "a.xyz", tmp_path / "b.xyz")
    os.symlink(tmp_path / "a.xyz", tmp_path / "c.xyz")
    monkeypatch.chdir(tmp_path)
    assert same_file("a.xyz", tmp_path / "b.xyz") and same_file("c.xyz", "a.xyz")
    assert same_file("new.xyz", tmp_path / "new.xyz") and not same_file("a.xyz", "new.xyz")
    with pytest.raises(InputError, match="is the input"):
        check_output("b.xyz", "--save-hbl", inputs=["a.xyz"])
