"""``arboretum demo``: the stage plan and its failure messages (fast), and the whole demo run (slow)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.cli import build_parser
from arboretum_library.commands import demo
from arboretum_library.errors import ArboretumError

PICTURES = ("1_scan.png", "2_hbl.png", "3_library.png", "4_assembly.png", "5_grown.png", "6_modular.png")
FILE_SUFFIXES = (".ply", ".npz", ".glb", ".usdc", ".yaml", ".json", ".png")


def _fake_run(returncode: int = 0, stdout: str = "", stderr: str = ""):
    def run(argv, **kwargs):
        return subprocess.CompletedProcess(argv, returncode, stdout, stderr)

    return run


def test_stage_plan_commands_exist_and_inputs_come_first():
    plan = demo.stages(7)
    names = [s.name for s in plan]
    assert len(names) == len(set(names)) == 17
    commands = set(build_parser()._subparsers._group_actions[0].choices)
    assert {s.argv[0] for s in plan} <= commands
    made = set(demo.SCRIPTS) | {"library"}
    for s in plan:
        inputs = [a for a in s.argv[1:] if a.endswith(FILE_SUFFIXES) and "/" not in a and a not in s.outputs]
        assert set(inputs) <= made, f"{s.name} reads {set(inputs) - made} before any stage writes it"
        made |= set(s.outputs)
    assert set(PICTURES) <= made
    assert {"modular_tree.glb", "modular_tree.usdc", "assembled_tree.glb", "session.npz", "tree_skeleton.json"} <= made
    merge_stage = next(s for s in plan if s.argv[:2] == ("assemble", "assembly.yaml"))
    assert merge_stage.check is demo.check_merged


def test_failed_stage_names_itself_and_the_last_error_line(tmp_path):
    stage = demo.Stage("bogus stage", ("nosuchcommand",))
    with pytest.raises(ArboretumError) as err:
        demo.run_stage(stage, tmp_path, 1, 1, runner=_fake_run(2, stderr="trace\narboretum: error: boom\n"))
    assert str(err.value) == "demo stage 'bogus stage' failed (exit 2): arboretum: error: boom"


def test_real_subprocess_failure_is_reported(tmp_path):
    with pytest.raises(ArboretumError, match=r"^demo stage 'bogus' failed \(exit 2\): .*nosuchcommand"):
        demo.run_stage(demo.Stage("bogus", ("nosuchcommand",)), tmp_path, 1, 1)


def test_missing_output_and_failed_check(tmp_path):
    with pytest.raises(ArboretumError, match="did not write x.glb"):
        demo.run_stage(demo.Stage("s", ("grow",), ("x.glb",)), tmp_path, 1, 1, runner=_fake_run())
    stage = demo.Stage("assemble", ("assemble",), check=demo.check_merged)
    with pytest.raises(ArboretumError, match="has no recombination merge"):
        demo.run_stage(stage, tmp_path, 1, 1, runner=_fake_run(stdout=json.dumps({"merges": []})))
    ok = demo.run_stage(stage, tmp_path, 1, 1, runner=_fake_run(stdout=json.dumps({"merges": [["a", "b", 3, 0]]})))
    assert ok["result"]["merges"] == [["a", "b", 3, 0]] and ok["argv"] == ["assemble"]
    check = demo.check_client(4)
    assert check({"errors": [], "placements": 4}) is None
    assert "3 placements, expected 4" in check({"errors": [], "placements": 3, "status": "add failed"})
    assert check({"errors": ["no library"], "placements": 4}) == "the client reported: no library"


def test_scripts_are_bundled_and_name_library_examples(tmp_path):
    demo.copy_scripts(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(demo.SCRIPTS)
    text = (tmp_path / "assembly.yaml").read_text()
    assert text.count("- add:") == 4 and "transform: {instance: top" in text


def test_no_client_without_display(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    assert demo.launch_client(tmp_path) is None
    assert not (tmp_path / "client.log").exists()


def test_summary_lists_stages_and_files(tmp_path):
    (tmp_path / "a.png").write_bytes(b"x" * 1234)
    (tmp_path / "library").mkdir()
    (tmp_path / "library" / "e.npz").write_bytes(b"y" * 10)
    files = demo.files_of(tmp_path)
    assert files == {"a.png": 1234, "library/": 10}
    text = demo.summary_text({"stages": [{"stage": "grow", "seconds": 1.5}], "files": files, "seconds": 2.0,
                              "cpu_seconds": 1.0, "out": str(tmp_path), "client": None})
    assert "   1.50 s  grow" in text and "     1,234  a.png" in text and "2.0 s wall, 1.0 s CPU" in text


# ---------------------------------------------------------------------------------------------- slow


def _content_fraction(path: Path) -> float:
    """Fraction of the picture's central half that is not background (saturated or dark pixels)."""
    from PIL import Image

    img = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255.0
    h, w, _ = img.shape
    c = img[h // 4: 3 * h // 4, w // 4: 3 * w // 4]
    hi, lo = c.max(axis=2), c.min(axis=2)
    sat = (hi - lo) / np.maximum(hi, 1e-6)
    return float(((sat > 0.25) | (hi < 0.35)).mean())


def _usd_instances(path: Path) -> int:
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    pis = [UsdGeom.PointInstancer(p) for p in stage.Traverse() if p.IsA(UsdGeom.PointInstancer)]
    assert pis, "no PointInstancer in the USD file"
    return sum(len(pi.GetProtoIndicesAttr().Get()) for pi in pis)


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    env = {**os.environ, "OMP_WAIT_POLICY": "PASSIVE"}
    proc = subprocess.run([sys.executable, "-m", "arboretum_library.cli", "demo", "--out", str(out), "--no-client",
                           "--json"], capture_output=True, text=True, env=env, timeout=280)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(proc.stdout)
    return out, summary, {s["stage"]: s["result"] for s in summary["stages"]}


@pytest.mark.slow
def test_demo_every_stage_and_library(demo_run):
    out, summary, results = demo_run
    assert [s["stage"] for s in summary["stages"]] == [s.name for s in demo.stages(7)]
    assert json.loads((out / "demo.json").read_text())["stages"][0]["stage"] == summary["stages"][0]["stage"]
    made = results["decompose it into HBL examples"]["examples"] + \
        results["decompose the real scan into the same library"]["examples"]
    assert len(made) == 16 and results["list the library"]["examples"] == 16
    assert summary["seconds"] < 120 and summary["client"] is None


@pytest.mark.slow
def test_demo_assembly_has_merge_link(demo_run):
    out, _, results = demo_run
    asm = results["assemble a new tree from 4 examples (recombination)"]
    assert asm["placements"] == ["trunk", "left", "right", "top"]
    assert ["trunk", "top"] in [m[:2] for m in asm["merges"]]
    moved = asm["operations"][-1]
    assert moved["op"] == "transform" and moved["merged"] == ["trunk"]
    from arboretum_library.assembly import Assembly
    from arboretum_library.codec import load_record

    assert len(load_record(out / "session.npz", Assembly).merges) == len(asm["merges"]) >= 3


@pytest.mark.slow
def test_demo_glb_and_usd(demo_run):
    from arboretum_library.export.gltf_read import read_glb

    out, _, results = demo_run
    mod = results["modular tree, instanced GLB"]
    meshes = read_glb(out / "modular_tree.glb")
    assert sum(len(m.faces) * len(m.instances) for m in meshes) == mod["triangles"] > 10_000
    assert sum(len(m.instances) for m in meshes) == mod["modules_placed"]
    grown = results["grow the assembled tree, export GLB"]["operations"][0]
    assert sum(len(m.faces) * len(m.instances) for m in read_glb(out / "assembled_tree.glb")) == grown["triangles"]
    usd = results["modular tree, USD"]
    assert _usd_instances(out / "modular_tree.usdc") == sum(len(m.instances) for m in meshes)
    assert usd["modules_placed"] == mod["modules_placed"]


@pytest.mark.slow
@pytest.mark.parametrize("picture", PICTURES)
def test_demo_pictures_show_something_in_the_centre(demo_run, picture):
    out, _, _ = demo_run
    assert _content_fraction(out / picture) > 0.02
