"""``arboretum demo``: the whole pipeline on bundled data, one stage after another, into one folder.

Each stage is an ``arboretum`` subcommand run as a child process, so the library (which owns this
command) never imports the server or the client, and what the demo does is exactly what a user can type.
The scripts it runs (``assets/demo/``: the assembly, its growth, two client scripts) are copied into OUT
first. Every stage's command line, output and timing go into ``OUT/demo.json``; pictures into
``OUT/*.png``. With a display (``DISPLAY`` set) and without ``--no-client``, the client is then started
on the demo's library (its ``load`` button opens ``OUT/session.npz``), without waiting for it.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from arboretum_library.assets import asset_path
from arboretum_library.checks import check_seed
from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import ArboretumError, InputError

SCRIPTS = ("assembly.yaml", "grow.yaml", "library_shot.json", "assembly_shot.json")
"""Files of ``assets/demo/`` copied into OUT before the stages run."""
PICTURE = ("--size", "960x540", "--json")
MARKER = ".arboretum-demo"
"""Written into OUT as a demo starts: tells a later run that the folder is a demo's own output."""


@dataclass(frozen=True)
class Stage:
    name: str
    """Short label printed while the stage runs."""
    argv: tuple[str, ...]
    """Arguments after ``arboretum``."""
    outputs: tuple[str, ...] = field(default=())
    """Files (relative to OUT) the stage must produce."""
    check: Callable[[Any], str | None] | None = None
    """Called with the stage's parsed ``--json`` output: a message when the result is wrong, else None."""


def check_merged(result: Any) -> str | None:
    """The assembly must hold at least one recombination merge link."""
    merges = result.get("merges", []) if isinstance(result, dict) else []
    return None if merges else "the assembly has no recombination merge (no two main branches came close enough)"


def check_client(placements: int) -> Callable[[Any], str | None]:
    """The headless client must end with ``placements`` examples placed and no error."""

    def check(result: Any) -> str | None:
        if not isinstance(result, dict):
            return "the client printed no JSON summary"
        if result.get("errors"):
            return f"the client reported: {result['errors'][0]}"
        if result.get("placements") != placements:
            return f"the client shows {result.get('placements')} placements, expected {placements} ({result.get('status')})"
        return None

    return check


def _pictures() -> list[Stage]:
    client = ("client", "--library", "library", "--out", ".", "--headless", "--size", "960x540", "--json",
              "--script")
    return [
        Stage("picture: the scan", ("render", "synth_scan.ply", "--out", "1_scan.png", *PICTURE), ("1_scan.png",)),
        Stage("picture: the decomposed HBL", ("render", "synth_hbl.npz", "--out", "2_hbl.png", "--view", "front",
                                              *PICTURE), ("2_hbl.png",)),
        Stage("picture: library examples (headless client)", (*client, "library_shot.json"), ("3_library.png",),
              check_client(4)),
        Stage("picture: the assembly (headless client)", (*client, "assembly_shot.json"), ("4_assembly.png",),
              check_client(4)),
        Stage("picture: the grown tree", ("render", "assembled_tree.glb", "--out", "5_grown.png", *PICTURE),
              ("5_grown.png",)),
        Stage("picture: the modular tree", ("render", "modular_tree.glb", "--out", "6_modular.png", *PICTURE),
              ("6_modular.png",)),
    ]


def stages(seed: int) -> list[Stage]:
    """The demo, in order. Paths are relative to OUT (the working directory of every stage)."""
    real = str(asset_path("scans", "06_adtree_tree7", "06_adtree_tree7.xyz"))
    s = str(seed)
    modules = ("modules", "--tree", "session.npz", "--library", "library", "--seed", s, "--json", "--out")
    return [
        Stage("inspect a bundled real scan", ("scan", "info", real, "--json")),
        Stage("synthesise a leaf-on tree with ground truth",
              ("synth", "--model", "guiding", "--species", "default", "--seed", s, "--points", "12000",
               "--out", "synth_scan.ply", "--truth", "synth_truth.npz", "--json"), ("synth_scan.ply", "synth_truth.npz")),
        Stage("decompose it into HBL examples",
              ("decompose", "synth_scan.ply", "--library", "library", "--save-hbl", "synth_hbl.npz", "--seed", s,
               "--json"), ("synth_hbl.npz",)),
        Stage("decompose the real scan into the same library",
              ("decompose", real, "--library", "library", "--save-hbl", "real_hbl.npz", "--json"), ("real_hbl.npz",)),
        Stage("list the library", ("library", "info", "library", "--json")),
        Stage("search the library", ("library", "search", "library", "dense", "curved", "--limit", "4", "--json")),
        Stage("assemble a new tree from 4 examples (recombination)",
              ("assemble", "assembly.yaml", "--library", "library", "--out", "session.npz", "--json"),
              ("session.npz",), check_merged),
        Stage("grow the assembled tree, export GLB",
              ("assemble", "grow.yaml", "--from", "session.npz", "--library", "library", "--out", "session.npz",
               "--json"), ("assembled_tree.glb",)),
        Stage("grow the decomposed tree, export GLB and skeleton",
              ("grow", "synth_hbl.npz", "--out", "tree.glb", "--skeleton", "tree_skeleton.json", "--seed", s,
               "--json"), ("tree.glb", "tree_skeleton.json")),
        Stage("modular tree, instanced GLB", (*modules, "modular_tree.glb"), ("modular_tree.glb",)),
        Stage("modular tree, USD", (*modules, "modular_tree.usdc"), ("modular_tree.usdc",)),
        *_pictures(),
    ]


def run_stage(stage: Stage, out: Path, index: int, total: int,
              runner: Callable[..., subprocess.CompletedProcess] = subprocess.run) -> dict:
    """Run one stage in ``out``; raise ``ArboretumError`` naming the stage when it fails."""
    argv = [sys.executable, "-m", "arboretum_library.cli", *stage.argv]
    print(f"[{index}/{total}] {stage.name}: arboretum {shlex.join(stage.argv)}", file=sys.stderr, flush=True)
    t0, c0 = time.perf_counter(), _child_cpu()
    proc = runner(argv, cwd=out, capture_output=True, text=True)
    seconds, cpu = time.perf_counter() - t0, _child_cpu() - c0
    if proc.returncode != 0:
        detail = (proc.stderr or "").strip().splitlines()[-1:] or ["(no message)"]
        raise ArboretumError(f"demo stage '{stage.name}' failed (exit {proc.returncode}): {detail[0]}")
    missing = [o for o in stage.outputs if not (out / o).is_file()]
    if missing:
        raise ArboretumError(f"demo stage '{stage.name}' did not write {', '.join(missing)}")
    try:
        result = json.loads(proc.stdout) if proc.stdout.strip() else None
    except json.JSONDecodeError:
        result = proc.stdout.strip()
    problem = stage.check(result) if stage.check else None
    if problem:
        raise ArboretumError(f"demo stage '{stage.name}' failed: {problem}")
    print(f"      done in {seconds:.2f} s", file=sys.stderr, flush=True)
    return {"stage": stage.name, "argv": list(stage.argv), "seconds": round(seconds, 3), "cpu_seconds": round(cpu, 3),
            "outputs": list(stage.outputs), "result": result}


def _child_cpu() -> float:
    t = os.times()
    return t.children_user + t.children_system


def copy_scripts(out: Path) -> None:
    """Copy the demo's scripts from ``assets/demo/`` into ``out``."""
    for name in SCRIPTS:
        shutil.copyfile(asset_path("demo", name), out / name)


def files_of(out: Path) -> dict[str, int]:
    """Bytes of every file directly in ``out`` (the library folder counted as one entry)."""
    sizes = {p.name: p.stat().st_size for p in sorted(out.iterdir()) if p.is_file() and p.name != MARKER}
    lib = out / "library"
    if lib.is_dir():
        sizes["library/"] = sum(p.stat().st_size for p in lib.rglob("*") if p.is_file())
    return sizes


def launch_client(out: Path) -> str | None:
    """Start the windowed client on the demo's library, not waiting for it; None without a display."""
    if not os.environ.get("DISPLAY"):
        return None
    log = open(out / "client.log", "w")  # noqa: SIM115 - handed to the child, closed when it exits
    argv = [sys.executable, "-m", "arboretum_library.cli", "client", "--library", "library", "--out", "."]
    subprocess.Popen(argv, cwd=out, stdout=log, stderr=log, start_new_session=True)
    return "arboretum client --library library --out . (press 'load' to open session.npz)"


def summary_text(summary: dict) -> str:
    lines = [f"{r['seconds']:7.2f} s  {r['stage']}" for r in summary["stages"]]
    lines += [f"  {size:>10,d}  {name}" for name, size in summary["files"].items()]
    lines.append(f"demo finished in {summary['seconds']} s wall, {summary['cpu_seconds']} s CPU; "
                 f"everything is in {summary['out']}")
    if summary["client"]:
        lines.append(f"client started: {summary['client']}")
    return "\n".join(lines)


def is_demo_output(out: Path) -> bool:
    """Whether the folder ``out`` was written by a demo (its marker, or the ``demo.json`` of a demo
    finished before the marker existed)."""
    if (out / MARKER).is_file():
        return True
    try:
        return "stages" in json.loads((out / "demo.json").read_text())
    except (OSError, ValueError, TypeError):
        return False


def prepare_out(out: Path) -> bool:
    """Make ``out`` ready for a demo: a new or empty folder, or a previous demo's, whose library is
    removed (a re-run would add every example again). Returns whether a previous demo is replaced.
    ``InputError`` for a file, or a folder holding anything else (the demo would overwrite it)."""
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: is a file, not a folder")
    replaced = out.is_dir() and any(out.iterdir())
    if replaced and not is_demo_output(out):
        names = sorted(p.name for p in out.iterdir())
        shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
        raise InputError(f"--out {out}: the folder holds files that are not a demo's ({shown}) and the demo "
                         "would overwrite them; give a new or empty folder")
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("written by 'arboretum demo'; a new demo run replaces this folder's demo files\n")
    if replaced and (out / "library").exists():
        shutil.rmtree(out / "library")
    return replaced


def run(args: argparse.Namespace) -> int:
    check_seed(args.seed)
    out = Path(args.out).resolve()
    if prepare_out(out):
        print(f"{out} holds a previous demo: replacing it (its library included)", file=sys.stderr, flush=True)
    copy_scripts(out)
    plan = stages(args.seed)
    t0, c0 = time.perf_counter(), _child_cpu()
    report = [run_stage(s, out, i + 1, len(plan)) for i, s in enumerate(plan)]
    summary = {"out": str(out), "seconds": round(time.perf_counter() - t0, 2),
               "cpu_seconds": round(_child_cpu() - c0, 2), "stages": report, "files": files_of(out),
               "client": None}
    (out / "demo.json").write_text(json.dumps(summary, indent=2) + "\n")
    if not args.no_client:
        summary["client"] = launch_client(out)
    emit(args, summary, summary_text(summary))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the whole pipeline on bundled data into a folder")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--seed", type=int, default=7, help="seed for every stochastic stage (default: 7)")
    p.add_argument("--no-client", action="store_true", help="do not start the client afterwards (with DISPLAY set)")
    add_json_flag(p)
    p.set_defaults(func=run)
