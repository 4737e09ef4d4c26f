"""``arboretum assemble`` as it runs (bug hunt s10: p8, p9, p10): transforms keep what they leave out,
a ``--from`` session is the floor of undo, exports reach their place only when the whole script
succeeded, and errors raised while building a request name the operation."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from arboretum_library.assembly import Assembly
from arboretum_library.cli import main
from arboretum_library.codec import load_record
from arboretum_library.geometry import axis_angle_matrix
from arboretum_server.assembly.script import Runner
from arboretum_server.assembly.script_check import Op, Pose
from factories import make_library


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return make_library(tmp_path_factory.mktemp("s10run") / "lib", 2)


def assemble(capsys, tmp_path, lib, text: str, *extra: str) -> tuple[int, str]:
    """Exit code and stderr of ``assemble`` on ``text``; --out is tmp_path/o.npz unless given."""
    (tmp_path / "s.yaml").write_text(text)
    out = [] if "--out" in extra else ["--out", str(tmp_path / "o.npz")]
    code = main(["assemble", str(tmp_path / "s.yaml"), "--library", str(lib), *out, *extra])
    return code, capsys.readouterr().err


def placements(path) -> dict:
    return {p.instance: p for p in load_record(path, Assembly).placements}


def rot_z(deg: float) -> np.ndarray:
    return axis_angle_matrix(np.array([0.0, 0, 1]), np.radians(deg))


# ---------------------------------------------------------------- p8: keys left out are kept
ADD_FAR = "- add: {example: ex-1, as: far, at: [4, 0, 0], rotate_z: 90, scale: 1.5}\n"


@pytest.mark.parametrize("transform, R, at, scale", [
    ("at: [3.5, 0, 0]", rot_z(90), [3.5, 0, 0], 1.5),  # docs/server.md's example
    ("rotate_z: 30", rot_z(30), [4, 0, 0], 1.5),
    ("rotate: [1, 0, 0, 90]", axis_angle_matrix(np.array([1.0, 0, 0]), np.radians(90)), [4, 0, 0], 1.5),
    ("scale: 0.5", rot_z(90), [4, 0, 0], 0.5),
    ("at: [5, 1, 0], scale: 2", rot_z(90), [5, 1, 0], 2.0),
    ("T: [[1, 0, 0, 6], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]", np.eye(3), [6, 0, 0], 1.5),
])
def test_transform_keeps_what_it_leaves_out(capsys, tmp_path, lib, transform, R, at, scale):
    code, err = assemble(capsys, tmp_path, lib, ADD_FAR + f"- transform: {{instance: far, {transform}}}\n")
    assert code == 0, err
    far = placements(tmp_path / "o.npz")["far"]
    assert np.array_equal(far.T_world_example[:3, :3], R)  # kept exactly, or the one given
    assert far.T_world_example[:3, 3].tolist() == at and far.scale == scale


def test_transform_lobe_keeps_what_it_leaves_out(capsys, tmp_path, lib):
    text = ("- add: {example: ex-0, as: a}\n"
            "- transform_lobe: {instance: a, lobe: 1, at: [0, 0.1, 0], rotate_z: 30, scale: 1.2}\n"
            "- transform_lobe: {instance: a, lobe: 1, scale: 1.5}\n"
            "- transform_lobe: {instance: a, lobe: 2, at: [0, 0, 0.3]}\n")
    code, err = assemble(capsys, tmp_path, lib, text)
    assert code == 0, err
    lts = {lt.lobe: lt.T_example_lobe for lt in placements(tmp_path / "o.npz")["a"].lobe_transforms}
    np.testing.assert_allclose(lts[1][:3, :3], 1.5 * rot_z(30), atol=1e-12)  # rotation kept, scale replaced
    assert lts[1][:3, 3].tolist() == [0, 0.1, 0]
    np.testing.assert_array_equal(lts[2], [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1]])


def test_transform_of_a_missing_instance_names_the_operation(capsys, tmp_path, lib):
    code, err = assemble(capsys, tmp_path, lib, "- add: {example: ex-0, as: a}\n- transform: {instance: b, scale: 2}\n")
    assert code == 2 and err.strip() == "arboretum assemble: error: operation 2 (transform): no placement 'b' in this session"


# ---------------------------------------------------------------- p9: the --from session is the undo floor
def test_undo_cannot_undo_loading_the_from_session(capsys, tmp_path, lib):
    session = tmp_path / "s.npz"
    code, _ = assemble(capsys, tmp_path, lib, "- add: {example: ex-0, as: a}\n", "--out", str(session))
    assert code == 0
    before = session.read_bytes()
    code, err = assemble(capsys, tmp_path, lib, "- undo: {}\n", "--from", str(session), "--out", str(session))
    assert code == 2 and "operation 1 (undo): nothing to undo" in err and err.count("\n") == 1
    assert session.read_bytes() == before  # not replaced by an empty session
    text = "- add: {example: ex-1, as: b}\n- undo: {}\n- redo: {}\n- undo: {}\n- undo: {}\n"
    code, err = assemble(capsys, tmp_path, lib, text, "--from", str(session))
    assert code == 2 and "operation 5 (undo): nothing to undo" in err
    code, err = assemble(capsys, tmp_path, lib, text.rsplit("- undo", 1)[0], "--from", str(session), "--json")
    assert code == 0, err
    assert list(placements(tmp_path / "o.npz")) == ["a"]


def test_from_with_a_missing_library_is_one_error_and_creates_nothing(capsys, tmp_path, lib):
    session = tmp_path / "s.npz"
    assert assemble(capsys, tmp_path, lib, "- add: {example: ex-0, as: a}\n", "--out", str(session))[0] == 0
    (tmp_path / "e.json").write_text("[]")
    missing = tmp_path / "nolib"
    code = main(["assemble", str(tmp_path / "e.json"), "--library", str(missing), "--from", str(session),
                 "--out", str(tmp_path / "p.npz")])
    err = capsys.readouterr().err
    assert code == 2 and "does not exist" in err and not missing.exists()  # it once created an empty library


# ---------------------------------------------------------------- p10: exports only with a whole script
def test_an_export_before_a_failing_operation_writes_nothing(capsys, tmp_path, lib):
    early = tmp_path / "early.glb"
    early.write_bytes(b"from an earlier run")
    text = (f"- add: {{example: ex-0, as: a}}\n- export: {{out: {early}, options: {{density: 0.3}}}}\n"
            "- delete: {instance: nope}\n")
    code, err = assemble(capsys, tmp_path, lib, text)
    assert code == 2 and err.strip().splitlines()[-1].endswith("operation 3 (delete): no placement 'nope' in this session")
    assert early.read_bytes() == b"from an earlier run"  # neither replaced nor removed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["early.glb", "s.yaml"]  # no temporary file left
    code, err = assemble(capsys, tmp_path, lib, text.rsplit("- delete", 1)[0], "--json")
    assert code == 0, err
    assert early.read_bytes()[:4] == b"glTF" and (tmp_path / "o.npz").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["early.glb", "o.npz", "s.yaml"]


def test_errors_raised_building_a_request_name_the_operation(tmp_path, lib):
    runner = Runner(lib, tmp_path / "state")
    try:
        bad = Op(2, "add", {"pose": Pose(scale=math.inf), "example": "ex-0", "instance": "a"})
        with pytest.raises(Exception, match=r"^operation 3 \(add\): assembly\.add\.scale: must be finite$"):
            runner.run(bad)
        nan = Op(3, "add", {"pose": Pose(at=np.array([0, np.nan, 0])), "example": "ex-0", "instance": "a"})
        with pytest.raises(Exception, match=r"^operation 4 \(add\): assembly\.add\.T_world_example: holds NaN"):
            runner.run(nan)
        assert runner.run(Op(4, "add", {"pose": Pose(), "example": "ex-0", "instance": "a"}))["instance"] == "a"
    finally:
        runner.close()


def test_json_summary_lists_each_operation(capsys, tmp_path, lib):
    text = ADD_FAR + "- transform: {instance: far, at: [3.5, 0, 0]}\n- undo: {}\n"
    (tmp_path / "s.yaml").write_text(text)
    assert main(["assemble", str(tmp_path / "s.yaml"), "--library", str(lib), "--out", str(tmp_path / "o.npz"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [r["label"] for r in data["operations"]] == ["add ex-1 as far", "transform far", "undo: transform far"]
    assert placements(tmp_path / "o.npz")["far"].T_world_example[:3, 3].tolist() == [4, 0, 0]


def test_an_export_waits_aside_until_commit_and_close_removes_it(tmp_path, lib):
    out = tmp_path / "t.glb"
    runner = Runner(lib, tmp_path / "state")
    try:
        runner.run(Op(0, "add", {"pose": Pose(), "example": "ex-0", "instance": "a"}))
        export = {"out": out, "format": "glb", "seed": 0, "lod": 0, "options": {"density": 0.3}}
        assert runner.run(Op(1, "export", export))["triangles"] > 100
        (tmp,) = [p for p in tmp_path.iterdir() if p.name.startswith(".t.glb.")]
        assert not out.exists() and tmp.read_bytes()[:4] == b"glTF"
    finally:
        runner.close()  # as after a failure or Ctrl-C: the staged file goes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state"]
