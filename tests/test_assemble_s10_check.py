"""``arboretum assemble``: the whole script is checked before it runs (bug hunt s10: p1, p5, p11, p15,
unknown keys). Each mistake is one line naming the operation and the key, and nothing is written."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.assembly import Assembly
from arboretum_library.cli import main
from arboretum_library.codec import load_record
from factories import make_library


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return make_library(tmp_path_factory.mktemp("s10check") / "lib", 2)


def assemble(capsys, tmp_path, lib, text: str, *extra: str, script: str = "s.yaml") -> tuple[int, str]:
    """Exit code and stderr of ``assemble`` on ``text``; --out is tmp_path/o.npz unless given."""
    path = tmp_path / script
    path.write_text(text)
    out = [] if "--out" in extra else ["--out", str(tmp_path / "o.npz")]
    code = main(["assemble", str(path), "--library", str(lib), *out, *extra])
    return code, capsys.readouterr().err


def one_line(code: int, err: str) -> str:
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err and "Warning" not in err, err
    return err


def snapshot(folder) -> dict:
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ---------------------------------------------------------------- p1: outputs inside the library
def test_out_inside_the_library_is_refused_and_the_example_kept(capsys, tmp_path, lib):
    before = snapshot(lib)
    code, err = assemble(capsys, tmp_path, lib, "- add: {example: ex-0}\n", "--out", str(lib / "examples" / "ex-0" / "arrays.npz"))
    assert "--out" in one_line(code, err) and "lies inside the library" in err
    assert snapshot(lib) == before


@pytest.mark.parametrize("out, message", [
    ("{lib}/examples/ex-1/t.glb", "operation 2 (export): out {lib}/examples/ex-1/t.glb: lies inside the library"),
    ("{lib}/x.obj", "operation 2 (export): out {lib}/x.zip: lies inside the library"),  # obj writes .zip
    ("{tmp}/s.ply", "operation 2 (export): out {tmp}/s.ply: is the input"),  # the script itself
    ("{tmp}/missing/t.glb", "operation 2 (export): out {tmp}/missing/t.glb: the folder {tmp}/missing does not exist"),
    ("{tmp}/t.stl", "operation 2 (export): out {tmp}/t.stl: writes .glb, .ply or .obj"),
])
def test_export_paths_are_checked_before_any_work(capsys, tmp_path, lib, out, message):
    before = snapshot(lib)
    text = "- add: {example: ex-0}\n- export: {out: OUT, options: {density: 0.3}}\n".replace(
        "OUT", out.format(lib=lib, tmp=tmp_path))
    code, err = assemble(capsys, tmp_path, lib, text, script="s.ply")
    assert message.format(lib=lib, tmp=tmp_path) in one_line(code, err)
    assert snapshot(lib) == before and not (tmp_path / "o.npz").exists()


def test_export_onto_the_from_session_or_twice_to_one_file_is_refused(capsys, tmp_path, lib):
    code, _ = assemble(capsys, tmp_path, lib, "- add: {example: ex-0}\n", "--out", str(tmp_path / "s.npz"))
    assert code == 0
    (tmp_path / "s.npz").rename(tmp_path / "s.glb")  # a session under an export's name
    code, err = assemble(capsys, tmp_path, lib, f"- export: {{out: {tmp_path}/s.glb}}\n", "--from", str(tmp_path / "s.glb"))
    assert f"operation 1 (export): out {tmp_path}/s.glb: is the input" in one_line(code, err)
    code, err = assemble(capsys, tmp_path, lib, f"- export: {{out: {tmp_path}/a.glb}}\n- export: {{out: {tmp_path}/a.glb}}\n")
    assert "operation 2 (export): out" in one_line(code, err) and "is also another output" in err


# ---------------------------------------------------------------- p5, p11, p15: values
EXPORT = "- add: {example: ex-0, as: a}\n- export: {out: t.glb, %s}\n"


@pytest.mark.parametrize("bad, message", [
    ("seed: abc", "operation 2 (export): seed must be a whole number >= 0, got 'abc'"),
    ("lod: x", "operation 2 (export): lod must be a whole number from 0 to 16, got 'x'"),
    ("options: 5", "operation 2 (export): options must be a map of growth options such as {density: 0.5}, got 5"),
    ("options: [1, 2]", "operation 2 (export): options must be a map of growth options"),
    ("seed: 1.9", "operation 2 (export): seed must be a whole number >= 0, got 1.9"),
    ("lod: 0.5", "operation 2 (export): lod must be a whole number from 0 to 16, got 0.5"),
    ("lod: true", "operation 2 (export): lod must be a whole number from 0 to 16, got true"),
    ("seed: 100000000000000000000000", "seed must be a whole number from 0 to 9223372036854775807, got 1000000"),
    ("options: {foo: 1}", "operation 2 (export): options: unknown growth option 'foo'; they are alpha, beta"),
    ("options: {density: abc}", "operation 2 (export): options: density must be a number, got 'abc'"),
    ("options: {max_iterations: 1.5}", "operation 2 (export): options: max_iterations must be a whole number"),
    ("options: {lobe_density: {x: 1}}", "operation 2 (export): options: lobe_density: lobe index must be a whole"),
    ("options: {branch_radii: 3}", "operation 2 (export): options: branch_radii must be text, got 3"),
    ("options: {kill: -1}", "operation 2 (export): grow option kill: must be > 0, got -1"),
])
def test_export_values_are_one_line_errors(capsys, tmp_path, lib, bad, message):
    code, err = assemble(capsys, tmp_path, lib, EXPORT % bad)
    assert message in one_line(code, err)
    assert not (tmp_path / "t.glb").exists()


@pytest.mark.parametrize("op, message", [
    ("transform_lobe: {instance: a, lobe: 1.7, scale: 1.2}", "operation 2 (transform_lobe): lobe must be a whole number >= 0, got 1.7"),
    ("transform_lobe: {instance: a, lobe: true, scale: 1.2}", "lobe must be a whole number >= 0, got true"),
    ("transform_lobe: {instance: a, lobe: 1, scale: 1e300}",
     "operation 2 (transform_lobe): scale must be a number from 1e-06 to 1e+06, got 1e+300"),
    ("transform: {instance: a, scale: .inf}", "operation 2 (transform): scale must be a number from 1e-06 to 1e+06, got inf"),
    ("transform: {instance: a, at: [0, .nan, 0]}", "operation 2 (transform): at must be a number from -1e+07 to 1e+07, got nan"),
    ("transform: {instance: a, at: [0, 0]}", "operation 2 (transform): at must be [x, y, z] (metres), got [0, 0]"),
    ("transform: {instance: a, rotate: [0, 0, 0, 45]}", "operation 2 (transform): rotate: the axis [0, 0, 0] is zero"),
    ("transform: {instance: a, rotate: [0, 0, 1]}", "rotate must be [axis x, axis y, axis z, degrees], got [0, 0, 1]"),
    ("transform: {instance: a, rotate_z: ninety}", "operation 2 (transform): rotate_z must be a number, got 'ninety'"),
    ("transform: {instance: a, T: [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]}",
     "operation 2 (transform): T: must be a rigid transform"),
    ("transform: {instance: a, T: [[1, 0, 0, 0]]}", "operation 2 (transform): T must be a 4x4 matrix"),
    ("transform: {instance: a, T: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], at: [1, 0, 0]}",
     "operation 2 (transform): give T or at, not both"),
    ("transform: {instance: a, rotate_z: 3, rotate: [0, 0, 1, 3]}", "operation 2 (transform): give rotate or rotate_z, not both"),
    ("transform: {instance: a}", "operation 2 (transform): nothing to change; give at, rotate, rotate_z, scale or T"),
    ("transform: {instance: [a], at: [0, 0, 0]}", "operation 2 (transform): instance must be a name, got ['a']"),
    ("sketch: {strokes: [[[0, 0, 0], [1, 2]]]}", "operation 2 (sketch): strokes: stroke 1, point 2 must be [x, y, z] (3 numbers), got [1, 2]"),
    ("sketch: {strokes: [[[0, 0, 0], [1, 2, x]]]}", "operation 2 (sketch): strokes: stroke 1, point 2 must be a number, got 'x'"),
    ("sketch: {strokes: [[[0, 0, 0], [0, 0, 1]], [[0, 0, .inf]]]}", "strokes: stroke 2, point 1 must be a finite number, got inf"),
    ("sketch: {strokes: [[[0, 0, 0], [0, 0, 1]], []]}", "operation 2 (sketch): strokes: stroke 2 must be a list of [x, y, z] points"),
    ("delete: {instance: {a: 1}}", "operation 2 (delete): instance must be a name"),
    ("add: {example: ex-0, as: b, rotatez: 120}",
     "operation 2 (add): unknown key 'rotatez'; add takes example, as, at, rotate, rotate_z, scale, T"),
    ("export: {out: o.glb, density: 50, foo: 1}",
     "operation 2 (export): unknown key 'density'; export takes out, seed, lod, options (growth options go inside options"),
    ("undo: {steps: 2}", "operation 2 (undo): unknown key 'steps'; undo takes no arguments"),
    ("delete: a", "operation 2 (delete): its arguments must be a map such as {instance: ...}"),
])
def test_operation_values_are_one_line_errors(capsys, tmp_path, lib, op, message):
    code, err = assemble(capsys, tmp_path, lib, f"- add: {{example: ex-0, as: a}}\n- {op}\n")
    assert message in one_line(code, err)
    assert not (tmp_path / "o.npz").exists()


def test_a_mistake_late_in_the_script_stops_it_before_the_first_operation(capsys, tmp_path, lib):
    text = (f"- export: {{out: {tmp_path}/early.glb}}\n- add: {{example: ex-0}}\n"
            f"- export: {{out: {tmp_path}/t.glb, options: {{density: 0.3}}}}\n- add: {{example: ex-1, scale: 0}}\n")
    code, err = assemble(capsys, tmp_path, lib, text)
    assert "operation 4 (add): scale must be a number from 1e-06 to 1e+06, got 0" in one_line(code, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]  # nothing grown, nothing written


def test_a_script_map_takes_name_and_ops_only(capsys, tmp_path, lib):
    code, err = assemble(capsys, tmp_path, lib, "name: t\nopz: []\nops: []\n")
    assert "unknown key 'opz'; a script map takes name and ops" in one_line(code, err)


def test_whole_numbers_given_as_2_0_and_yaml_exponents_are_taken(capsys, tmp_path, lib):
    text = ("- add: {example: ex-0, as: a, scale: 1e-3, at: [1e2, 0, 0]}\n"
            "- transform_lobe: {instance: a, lobe: 1.0, scale: 2E+0}\n")
    code, err = assemble(capsys, tmp_path, lib, text)
    assert code == 0, err
    (p,) = load_record(tmp_path / "o.npz", Assembly).placements
    assert p.scale == 0.001 and p.T_world_example[0, 3] == 100.0
    assert [lt.lobe for lt in p.lobe_transforms] == [1]
    np.testing.assert_allclose(p.lobe_transforms[0].T_example_lobe[:3, :3], 2 * np.eye(3), atol=1e-12)
