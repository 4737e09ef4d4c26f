"""Ctrl-C while ``assemble`` writes ``--out`` and renames its exports into place (review s10, finding 6):
the interrupt waits for the last rename, so the files are the old set or the new one, never a mix.
A real SIGINT is sent to this process at the chosen moment (as a Ctrl-C would be)."""

from __future__ import annotations

import os
import signal

import pytest

from arboretum_library import codec
from arboretum_library.assembly import Assembly
from arboretum_library.cli import main
from arboretum_server.assembly import script
from factories import make_library

OLD = {"a.glb": b"old a", "b.glb": b"old b", "o.npz": b"old session"}


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return make_library(tmp_path_factory.mktemp("review_commit") / "lib", 1)


@pytest.fixture
def folder(tmp_path):
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # Ctrl-C raises here, as on the CLI
    for name, data in OLD.items():
        (tmp_path / name).write_bytes(data)
    (tmp_path / "s.yaml").write_text(f"- add: {{example: ex-0, as: a}}\n- export: {{out: {tmp_path}/a.glb}}\n"
                                     f"- export: {{out: {tmp_path}/b.glb}}\n")
    return tmp_path


def _run(folder, lib, capsys) -> int:
    code = main(["assemble", str(folder / "s.yaml"), "--library", str(lib), "--out", str(folder / "o.npz")])
    capsys.readouterr()
    return code


def _assert_new_set(folder) -> None:
    assert (folder / "a.glb").read_bytes()[:4] == (folder / "b.glb").read_bytes()[:4] == b"glTF"
    assert [p.instance for p in codec.load_record(folder / "o.npz", Assembly).placements] == ["a"]
    assert sorted(p.name for p in folder.iterdir()) == ["a.glb", "b.glb", "o.npz", "s.yaml"]  # no temp file


def test_ctrl_c_between_two_export_renames_lands_the_whole_new_set(folder, lib, capsys, monkeypatch):
    real = os.replace

    def replace(src, dst):
        if str(dst).endswith("b.glb"):
            os.kill(os.getpid(), signal.SIGINT)
        return real(src, dst)

    monkeypatch.setattr(script.os, "replace", replace)
    assert _run(folder, lib, capsys) == 130  # still reported as interrupted
    _assert_new_set(folder)


def test_ctrl_c_while_the_session_is_written_lands_the_whole_new_set(folder, lib, capsys, monkeypatch):
    real = codec.save_record

    def save_record(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return real(*args, **kwargs)

    monkeypatch.setattr(codec, "save_record", save_record)
    assert _run(folder, lib, capsys) == 130
    _assert_new_set(folder)


def test_ctrl_c_before_the_commit_keeps_the_whole_old_set(folder, lib, capsys, monkeypatch):
    real = script.Runner.assembly

    def assembly(self):
        os.kill(os.getpid(), signal.SIGINT)
        return real(self)

    monkeypatch.setattr(script.Runner, "assembly", assembly)
    assert _run(folder, lib, capsys) == 130
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.name != "s.yaml"} == OLD
