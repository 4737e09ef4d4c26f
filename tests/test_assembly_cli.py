"""``arboretum assemble``: a YAML/JSON script run through the server's handlers, no socket."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arboretum_library.assembly import Assembly
from arboretum_library.cli import main
from arboretum_library.codec import load_record
from arboretum_library.store import Library
from factories import make_example

SCRIPT = """
name: demo
ops:
  - add: {example: ex-0, as: trunk}
  - add: {example: ex-1, as: limb, at: [0.0, 0.0, 0.4], rotate: [0, 1, 0, 30]}
  - add: {example: ex-2, as: far, at: [4, 0, 0], rotate_z: 90, scale: 1.5}
  - transform_lobe: {instance: trunk, lobe: 0, at: [0, 0.1, 0], scale: 1.2}
  - sketch: {as: drawn, strokes: [[[8, 0, 0], [8, 0, 1], [8, 0, 2]], [[8.2, 0, 2], [8, 0.2, 2], [7.8, 0, 2], [8, -0.2, 2], [8.19, 0, 2]]]}
  - delete: {instance: far}
  - undo: {}
  - export: {out: OUT, options: {density: 0.3}}
"""


@pytest.fixture
def lib(tmp_path):
    rng = np.random.default_rng(8)
    with Library.open(tmp_path / "lib", create=True) as lb:
        for i in range(3):
            lb.add(make_example(rng, id=f"ex-{i}", n_lobes=3))
    return tmp_path / "lib"


def test_yaml_script_builds_the_session(tmp_path, lib, capsys):
    script = tmp_path / "s.yaml"
    script.write_text(SCRIPT.replace("OUT", str(tmp_path / "tree.glb")))
    out = tmp_path / "session.npz"
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["placements"] == ["trunk", "limb", "far", "drawn"]  # the delete was undone
    assert [m[:2] for m in data["merges"]] == [["trunk", "limb"]]
    assert data["operations"][4]["kinds"] == ["branch", "lobe"]
    assert data["operations"][-1]["triangles"] > 100
    a = load_record(out, Assembly)
    far = {p.instance: p for p in a.placements}["far"]
    assert far.scale == 1.5 and np.allclose(far.T_world_example[:3, 0], [0, 1, 0], atol=1e-12)
    assert {p.instance: p for p in a.placements}["trunk"].lobe_transforms[0].T_example_lobe[0, 0] == pytest.approx(1.2)
    assert (tmp_path / "tree.glb").read_bytes()[:4] == b"glTF"
    # start again from the saved session, as JSON
    js = tmp_path / "more.json"
    js.write_text(json.dumps([{"delete": {"instance": "limb"}}]))
    out2 = tmp_path / "s2.npz"
    assert main(["assemble", str(js), "--library", str(lib), "--out", str(out2), "--from", str(out)]) == 0
    assert [p.instance for p in load_record(out2, Assembly).placements] == ["trunk", "far", "drawn"]


@pytest.mark.parametrize("text, message", [
    ("- add: {as: x}", "operation 1 (add): missing argument 'example'"),
    ("- fly: {}", "operation 1 (fly): unknown operation"),
    ("- add: {example: nope}", "operation 1 (add): no example 'nope'"),
    ("add: 3", "expected a list of one-key maps"),
    ("- [unclosed", "not valid YAML"),
    # an export takes grow's limits (density 1000 wrote 258 MB; a negative seed was a traceback)
    ("- add: {example: ex-0}\n- export: {out: t.glb, options: {density: 1000}}",
     "operation 2 (export): growth option density must be a number > 0 and <= 20, got 1000"),
    ("- add: {example: ex-0}\n- export: {out: t.glb, seed: -3}", "operation 2 (export): seed must not be negative"),
    ("- add: {example: ex-0}\n- export: {out: t.glb, lod: 99}",
     "operation 2 (export): lod must be a whole number from 0 to 16, got 99"),
])
def test_script_mistakes_are_one_line_errors(tmp_path, lib, capsys, text, message):
    script = tmp_path / "bad.yaml"
    script.write_text(text)
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "o.npz")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "o.npz").exists()
