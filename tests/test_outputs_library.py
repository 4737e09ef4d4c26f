"""Outputs inside a library the command uses are refused before any work (``outputs.check_output``):
``assemble --out LIB/examples/X/arrays.npz`` once replaced an example's arrays."""

from __future__ import annotations

import os

import pytest

from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_library.outputs import check_output, inside


def test_inside_resolves_links_and_missing_paths(tmp_path):
    lib = tmp_path / "lib"
    (lib / "examples" / "a-0001").mkdir(parents=True)
    os.symlink(lib, tmp_path / "alias")
    assert inside(lib / "examples" / "a-0001" / "arrays.npz", lib)
    assert inside(tmp_path / "alias" / "catalog.sqlite", lib)  # through a link
    assert inside(lib / "new.glb", lib) and inside(lib, lib)
    assert not inside(tmp_path / "library2" / "x.glb", lib)  # a sibling with the same prefix
    assert not inside(tmp_path / "out.glb", lib)


def test_check_output_refuses_a_path_in_a_library(tmp_path):
    lib = tmp_path / "lib"
    (lib / "examples").mkdir(parents=True)
    with pytest.raises(InputError, match=r"--out .*arrays\.npz: lies inside the library .*lib"):
        check_output(lib / "examples" / "arrays.npz", "--out", libraries=[None, lib])
    assert check_output(tmp_path / "t.glb", "--out", libraries=[None, lib]) == tmp_path / "t.glb"


@pytest.mark.parametrize("argv", [
    ["grow", "{hbl}", "--out", "{lib}/tree.glb", "--library", "{lib}"],
    ["modules", "--tree", "{hbl}", "--out", "{lib}/examples/m.glb", "--library", "{lib}"],
    ["decompose", "{scan}", "--library", "{lib}", "--save-hbl", "{lib}/catalog.npz"],
])
def test_commands_refuse_outputs_in_their_library(tmp_path, capsys, argv):
    lib = tmp_path / "lib"
    (lib / "examples").mkdir(parents=True)
    before = sorted(p.name for p in lib.rglob("*"))
    hbl, scan = tmp_path / "h.npz", tmp_path / "s.xyz"
    hbl.write_bytes(b"not read")
    scan.write_text("0 0 0\n1 1 1\n")
    code = main([a.format(lib=lib, hbl=hbl, scan=scan) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and "lies inside the library" in err and "Traceback" not in err
    assert sorted(p.name for p in lib.rglob("*")) == before  # nothing written there
