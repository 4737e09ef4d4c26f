"""``arboretum assemble`` puts ``--out`` and every export in place all or none (helper-81): an ``OSError``
on any rename leaves every destination as it was (bytes identical, a missing file still missing), no
hidden file behind, and one error line naming the destination and the problem (exit 2)."""

from __future__ import annotations

import errno
import os
import signal
from pathlib import Path

import pytest

from arboretum_library.atomic import set_aside
from arboretum_library.cli import main
from arboretum_library.errors import InputError
from arboretum_server.assembly.script import Runner, Staged, swap
from factories import make_library

PID = os.getpid()


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return make_library(tmp_path_factory.mktemp("s11commit") / "lib", 1)


def scene(tmp_path: Path, lib: Path, *, missing: str = "c.glb") -> tuple[Path, dict[str, bytes | None]]:
    """A folder with a.glb, b.glb, o.npz from an earlier run (``missing`` absent) and a script exporting
    a, b and c; the folder's contents by name (None: absent)."""
    d = tmp_path / "w"
    d.mkdir()
    names = ["a.glb", "b.glb", "c.glb", "o.npz"]
    for n in names:
        if n != missing:
            (d / n).write_bytes(f"earlier {n}".encode())
    exports = "".join(f"- export: {{out: {d / n}, options: {{density: 0.3}}}}\n" for n in names[:3])
    (tmp_path / "s.yaml").write_text("- add: {example: ex-0, as: t}\n" + exports)
    return d, {n: (None if n == missing else f"earlier {n}".encode()) for n in names}


def contents(d: Path) -> dict[str, bytes | None]:
    """Every entry of ``d`` (hidden ones included) by name: its bytes, or None for a folder."""
    return {p.name: None if p.is_dir() else p.read_bytes() for p in sorted(d.iterdir())}


def assemble(capsys, tmp_path: Path, lib: Path, *extra: str) -> tuple[int, str]:
    code = main(["assemble", str(tmp_path / "s.yaml"), "--library", str(lib), "--json",
                 "--out", str(tmp_path / "w" / "o.npz"), *extra])
    return code, capsys.readouterr().err


def failing_replace(monkeypatch, fail: dict[str, list[OSError | None]]) -> list[str]:
    """Make the k-th ``os.replace`` to a file named ``name`` raise ``fail[name][k]`` (None: rename);
    the names renamed to, in order."""
    real, seen = os.replace, []

    def replace(src, dst, *a, **k):
        name = Path(dst).name
        seen.append(name)
        if fail.get(name) and (exc := fail[name].pop(0)) is not None:
            raise exc
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", replace)
    return seen


# ---------------------------------------------------------------- through the command
@pytest.mark.parametrize("target, what", [
    ("a.glb", "operation 2 (export): out"),  # the first rename: nothing placed yet
    ("c.glb", "operation 4 (export): out"),  # a and b placed, then undone; c was missing and stays so
    ("o.npz", "--out"),  # the last rename: every export placed, then undone
])
def test_a_failing_rename_leaves_every_file_as_it_was(capsys, monkeypatch, tmp_path, lib, target, what):
    d, before = scene(tmp_path, lib)
    seen = failing_replace(monkeypatch, {target: [OSError(errno.EXDEV, os.strerror(errno.EXDEV))]})
    code, err = assemble(capsys, tmp_path, lib)
    assert code == 2
    assert err == f"arboretum assemble: error: {what} {d / target}: cannot be replaced (Invalid cross-device " \
                  "link); no file was changed\n"
    assert contents(d) == {n: b for n, b in before.items() if b is not None}  # no .tmp nor .old left
    assert seen[seen.index(target) + 1:] == {"a.glb": [], "c.glb": ["b.glb", "a.glb"],
                                             "o.npz": ["b.glb", "a.glb"]}[target]  # undone in reverse (c removed)


def test_a_destination_that_became_a_folder_is_named_and_nothing_changes(capsys, monkeypatch, tmp_path, lib):
    d, before = scene(tmp_path, lib)
    call, exports = Runner._call, []

    def call_then_mkdir(self, req, progress=None):
        reply = call(self, req, progress)
        exports.append(type(req).__name__ == "ExportMesh")
        if exports[-1] and sum(exports) == 3:  # c.glb made a folder (holding a file) while the script runs
            (d / "c.glb").mkdir()
            (d / "c.glb" / "keep.txt").write_bytes(b"mine")
        return reply

    monkeypatch.setattr(Runner, "_call", call_then_mkdir)
    code, err = assemble(capsys, tmp_path, lib)
    assert code == 2 and err == (f"arboretum assemble: error: operation 4 (export): out {d / 'c.glb'}: "
                                 "cannot be replaced (it is a folder now); no file was changed\n")
    assert contents(d) == {**{n: b for n, b in before.items() if b is not None}, "c.glb": None}
    assert (d / "c.glb" / "keep.txt").read_bytes() == b"mine"


def test_a_real_failure_after_a_rename_undoes_it(capsys, monkeypatch, tmp_path, lib):
    """b.glb's new file vanishes before the swap: its rename fails in the kernel (ENOENT) after a.glb's
    new file was really put in place; a.glb really gets its old file back, and c.glb stays missing."""
    d, before = scene(tmp_path, lib)
    commit = Runner.commit

    def commit_without_b(self):
        (tmp,) = d.glob(".b.glb.*.tmp")
        tmp.unlink()
        commit(self)

    monkeypatch.setattr(Runner, "commit", commit_without_b)
    code, err = assemble(capsys, tmp_path, lib)
    assert code == 2 and err == (f"arboretum assemble: error: operation 3 (export): out {d / 'b.glb'}: "
                                 "cannot be replaced (No such file or directory); no file was changed\n")
    assert contents(d) == {n: b for n, b in before.items() if b is not None}


def test_success_replaces_all_and_leaves_nothing_hidden(capsys, tmp_path, lib):
    d, _ = scene(tmp_path, lib, missing="b.glb")
    code, err = assemble(capsys, tmp_path, lib)
    assert code == 0, err
    after = contents(d)
    assert sorted(after) == ["a.glb", "b.glb", "c.glb", "o.npz"]
    assert all(after[n][:4] == b"glTF" for n in ("a.glb", "b.glb", "c.glb")) and after["o.npz"][:2] == b"PK"


def test_out_that_is_the_from_session_keeps_its_bytes_on_failure(capsys, monkeypatch, tmp_path, lib):
    d, _ = scene(tmp_path, lib)
    (tmp_path / "s.yaml").write_text("- add: {example: ex-0, as: t}\n")
    assert assemble(capsys, tmp_path, lib)[0] == 0
    session = (d / "o.npz").read_bytes()
    export = f"- export: {{out: {d / 'a.glb'}, options: {{density: 0.3}}}}\n"
    (tmp_path / "s.yaml").write_text("- add: {example: ex-0, as: u}\n" + export)
    failing_replace(monkeypatch, {"a.glb": [PermissionError(errno.EACCES, "Permission denied")]})
    code, err = assemble(capsys, tmp_path, lib, "--from", str(d / "o.npz"))
    assert code == 2 and err.count("\n") == 1 and "out " + str(d / "a.glb") + ": cannot be replaced" in err
    assert (d / "o.npz").read_bytes() == session and (d / "a.glb").read_bytes() == b"earlier a.glb"


# ---------------------------------------------------------------- swap itself, on plain files
def staged(d: Path, names: list[str], old: dict[str, bytes]) -> list[Staged]:
    """Destinations d/NAME (holding ``old[NAME]`` when given) with new files 'new NAME' written aside."""
    out = []
    for i, n in enumerate(names):
        if n in old:
            (d / n).write_bytes(old[n])
        tmp = d / f".{n}.{PID}-{i}.tmp"
        tmp.write_bytes(f"new {n}".encode())
        out.append(Staged(tmp, d / n, f"thing {i}"))
    return out


def test_without_hard_links_files_are_moved_aside_and_back(monkeypatch, tmp_path):
    def no_link(*a, **k):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_link)
    old = {"x": b"old x", "z": b"old z"}
    failing_replace(monkeypatch, {"z": [OSError(errno.ENOSPC, "No space left on device")]})
    with pytest.raises(InputError, match=r"^thing 2 \S+/z: cannot be replaced \(No space left on device\); "
                                         r"no file was changed$"):
        swap(staged(tmp_path, ["x", "y", "z"], old))
    assert contents(tmp_path) == old
    monkeypatch.undo()  # os.link and os.replace as they are: a swap that succeeds
    monkeypatch.setattr(os, "link", no_link)
    swap(staged(tmp_path, ["x", "y"], old))
    assert contents(tmp_path) == {"x": b"new x", "y": b"new y", "z": b"old z"}


def test_a_failed_undo_says_where_the_previous_file_is(monkeypatch, tmp_path):
    failing_replace(monkeypatch, {"y": [OSError(errno.EIO, "Input/output error")],
                                  "x": [None, OSError(errno.EROFS, "Read-only file system")]})  # putting x back
    with pytest.raises(InputError) as e:
        swap(staged(tmp_path, ["x", "y"], {"x": b"old x", "y": b"old y"}))
    kept = tmp_path / f".x.{PID}-0.old"
    assert str(e.value) == (f"thing 1 {tmp_path / 'y'}: cannot be replaced (Input/output error); could not "
                            f"put back {tmp_path / 'x'} (its previous file is {kept}: Read-only file system)")
    assert contents(tmp_path) == {kept.name: b"old x", "x": b"new x", "y": b"old y"}


def test_an_old_name_left_by_a_killed_run_is_never_touched(tmp_path):
    stale = tmp_path / f".x.{PID}-0.old"
    stale.write_bytes(b"left by a SIGKILL")
    failing = staged(tmp_path, ["x"], {"x": b"old x"})
    old, linked = set_aside(failing[0].tmp, failing[0].out)
    assert old == tmp_path / f".x.{PID}-0.1.old" and linked and old.read_bytes() == b"old x"
    old.unlink()
    swap(failing)
    assert contents(tmp_path) == {stale.name: b"left by a SIGKILL", "x": b"new x"}


def test_ctrl_c_during_the_swap_waits_for_the_last_rename(monkeypatch, tmp_path):
    real = os.replace

    def replace_and_interrupt(src, dst, *a, **k):
        os.kill(PID, signal.SIGINT)
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", replace_and_interrupt)
    with pytest.raises(KeyboardInterrupt):
        swap(staged(tmp_path, ["x", "y"], {"x": b"old x"}))
    assert contents(tmp_path) == {"x": b"new x", "y": b"new y"}


def test_a_link_as_destination_is_put_back_as_a_link(monkeypatch, tmp_path):
    (tmp_path / "target").write_bytes(b"the link's target")
    (tmp_path / "x").symlink_to("target")
    failing_replace(monkeypatch, {"y": [OSError(errno.EIO, "Input/output error")]})
    with pytest.raises(InputError, match=r"cannot be replaced \(Input/output error\); no file was changed$"):
        swap(staged(tmp_path, ["x", "y"], {}))
    assert os.readlink(tmp_path / "x") == "target" and (tmp_path / "target").read_bytes() == b"the link's target"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["target", "x"]
