"""OBJ sidecars are named after the OBJ (tree.mtl, tree_bark.png, tree_leaf.png), files Arboretum did not
write are refused, and an error or interrupt while writing leaves no file behind."""

from __future__ import annotations

import tempfile

import numpy as np
import pytest
import trimesh

import arboretum_library.export.obj as obj
from arboretum_library.assets import asset_path
from arboretum_library.errors import InputError
from arboretum_library.export.obj import write_obj
from arboretum_library.export.parts import Material, MeshPart

BARK = asset_path("textures", "bark.png").read_bytes()
LEAF = asset_path("textures", "leaf.png").read_bytes()


def _scene():
    box = trimesh.creation.box((1, 1, 3))
    uv = np.random.default_rng(0).uniform(size=(8, 2))
    bark = MeshPart("bark", box.vertices, box.faces, box.vertex_normals, uv, 0)
    card = MeshPart("leaves", np.array([[0, 0, 2], [0.1, 0, 2], [0.1, 0, 2.2], [0, 0, 2.2]]),
                    np.array([[0, 1, 2], [0, 2, 3]]), None, np.array([[0, 1], [1, 1], [1, 0], [0, 0.0]]), 1)
    mats = [Material("bark", texture_png=BARK, texture_name="bark.png"),
            Material("leaf", texture_png=LEAF, texture_name="leaf.png", alpha_cutoff=0.5)]
    return [bark, card], mats


def _swapped_textures() -> list[Material]:
    """The scene's two materials with their textures swapped: a re-export whose files all differ."""
    return [Material("bark", texture_png=LEAF, texture_name="bark.png"),
            Material("leaf", texture_png=BARK, texture_name="leaf.png", alpha_cutoff=0.5)]


def _names(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_sidecars_are_named_after_the_obj_and_load(tmp_path):
    files = write_obj(tmp_path / "tree.obj", *_scene())
    assert [f.name for f in files] == ["tree.obj", "tree.mtl", "tree_bark.png", "tree_leaf.png"]
    assert _names(tmp_path) == ["tree.mtl", "tree.obj", "tree_bark.png", "tree_leaf.png"]
    mtl = (tmp_path / "tree.mtl").read_text()
    assert "map_Kd tree_bark.png" in mtl and "map_d tree_leaf.png" in mtl
    assert (tmp_path / "tree_leaf.png").read_bytes() == LEAF
    scene = trimesh.load(tmp_path / "tree.obj", process=False)
    images = [g.visual.material.image for g in scene.geometry.values()]
    assert len(images) == 2 and all(im is not None for im in images)
    assert sorted(im.size for im in images) == [(128, 256), (256, 256)]


def test_two_exports_in_one_folder_do_not_clobber(tmp_path):
    write_obj(tmp_path / "a.obj", *_scene())
    before = {n: (tmp_path / n).read_bytes() for n in _names(tmp_path)}
    parts, mats = _scene()
    mats[1] = Material("leaf", texture_png=BARK, texture_name="leaf.png")  # b's "leaf" differs
    write_obj(tmp_path / "b.obj", parts, mats)
    assert len(_names(tmp_path)) == 8
    assert {n: (tmp_path / n).read_bytes() for n in before} == before
    assert (tmp_path / "b_leaf.png").read_bytes() == BARK
    write_obj(tmp_path / "a.obj", *_scene())  # exporting again over our own files is fine
    assert len(_names(tmp_path)) == 8


@pytest.mark.parametrize("name, content", [("tree.mtl", b"newmtl mine\n"),
                                           ("tree_leaf.png", b"MY OWN HAND-PAINTED LEAF")])
def test_files_not_ours_are_refused_and_kept(tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(InputError, match=f"{name}: exists and was not written by Arboretum"):
        write_obj(tmp_path / "tree.obj", *_scene())
    assert (tmp_path / name).read_bytes() == content
    assert _names(tmp_path) == [name]


def test_identical_texture_without_mtl_is_replaced(tmp_path):
    (tmp_path / "tree_leaf.png").write_bytes(LEAF)
    write_obj(tmp_path / "tree.obj", *_scene())
    assert len(_names(tmp_path)) == 4


@pytest.mark.parametrize("calls", [1, 3, 4])
def test_interrupt_while_writing_leaves_nothing(tmp_path, monkeypatch, calls):
    real = tempfile.mkstemp
    seen = []

    def mkstemp(*args, **kwargs):
        seen.append(1)
        if len(seen) == calls:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    with pytest.raises(KeyboardInterrupt):
        write_obj(tmp_path / "tree.obj", *_scene())
    assert _names(tmp_path) == []


def test_interrupt_while_formatting_leaves_nothing(tmp_path, monkeypatch):
    def slow(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(obj, "obj_text", slow)
    with pytest.raises(KeyboardInterrupt):
        write_obj(tmp_path / "tree.obj", *_scene())
    assert _names(tmp_path) == []


def test_interrupt_keeps_the_previous_export(tmp_path, monkeypatch):
    """The re-export has other textures, so a mix of old and new files would show (before: the new
    tree_leaf.png was renamed beside the old .mtl and .obj)."""
    write_obj(tmp_path / "tree.obj", *_scene())
    before = {n: (tmp_path / n).read_bytes() for n in _names(tmp_path)}
    real = obj.os.replace

    def replace(src, dst):
        if str(dst).endswith(".mtl"):
            raise KeyboardInterrupt
        return real(src, dst)

    monkeypatch.setattr(obj.os, "replace", replace)
    parts, _ = _scene()
    mats = _swapped_textures()
    with pytest.raises(KeyboardInterrupt):
        write_obj(tmp_path / "tree.obj", parts[:1], mats)
    assert {n: (tmp_path / n).read_bytes() for n in _names(tmp_path)} == before


def test_ctrl_c_during_the_renames_is_held_back_until_the_set_is_whole(tmp_path, monkeypatch):
    """A real SIGINT at the first rename: every file is the new one, then KeyboardInterrupt."""
    import signal

    write_obj(tmp_path / "tree.obj", *_scene())
    real, calls = obj.os.replace, []

    def replace(src, dst):
        if not calls:
            signal.raise_signal(signal.SIGINT)
        calls.append(str(dst))
        return real(src, dst)

    monkeypatch.setattr(obj.os, "replace", replace)
    parts, _ = _scene()
    mats = _swapped_textures()
    with pytest.raises(KeyboardInterrupt):
        write_obj(tmp_path / "tree.obj", parts[:1], mats)
    assert [p.rsplit("/", 1)[1] for p in calls] == ["tree.mtl", "tree_bark.png", "tree_leaf.png", "tree.obj"]
    assert (tmp_path / "tree_bark.png").read_bytes() == LEAF and (tmp_path / "tree_leaf.png").read_bytes() == BARK
    assert (tmp_path / "tree.mtl").read_text() == obj.mtl_text(mats, "tree")
    assert (tmp_path / "tree.obj").read_text() == obj.obj_text(parts[:1], mats, "tree.mtl")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert _names(tmp_path) == ["tree.mtl", "tree.obj", "tree_bark.png", "tree_leaf.png"]


def test_a_broken_first_export_does_not_block_the_next(tmp_path, monkeypatch):
    """The .mtl, which records what Arboretum owns, is renamed first: a first export broken after it
    leaves textures a re-export with other bytes may replace (before: a lone tree_bark.png, no .mtl, and
    the re-export was refused as "not written by Arboretum")."""
    real, calls = obj.os.replace, []

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError("disk full")
        return real(src, dst)

    monkeypatch.setattr(obj.os, "replace", replace)
    parts, mats = _scene()
    with pytest.raises(OSError):
        write_obj(tmp_path / "tree.obj", parts, mats)
    monkeypatch.setattr(obj.os, "replace", real)
    assert not any(n.endswith(".tmp") for n in _names(tmp_path))
    mats = _swapped_textures()
    write_obj(tmp_path / "tree.obj", parts, mats)
    assert (tmp_path / "tree_bark.png").read_bytes() == LEAF and (tmp_path / "tree_leaf.png").read_bytes() == BARK


def test_writes_never_touch_the_process_umask(tmp_path, monkeypatch):
    """The file mode comes from the umask read once at import (toggling it per write races with other
    threads creating files in a threaded server)."""
    import os

    from arboretum_library.export.gltf import write_glb

    mask = os.umask(0o022)
    os.umask(mask)

    def umask(value):
        raise AssertionError("os.umask called while writing")

    monkeypatch.setattr(obj.os, "umask", umask)
    write_obj(tmp_path / "tree.obj", *_scene())
    write_glb(tmp_path / "tree.glb", *_scene())
    for name in ("tree.obj", "tree.mtl", "tree_leaf.png", "tree.glb"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~mask
