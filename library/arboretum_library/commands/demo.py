"""``arboretum demo``: the whole pipeline on bundled data, one stage after another, into one folder.

Each stage is an ``arboretum`` subcommand run as a child process, so the library (which owns this
command) never imports the server or the client, and what the demo does is exactly what a user can type.
Every stage's command line, output and timing go into ``OUT/demo.json``; pictures into ``OUT/*.png``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from arboretum_library.assets import asset_path
from arboretum_library.cli import add_json_flag, emit
from arboretum_library.errors import ArboretumError


@dataclass(frozen=True)
class Stage:
    name: str
    """Short label printed while the stage runs."""
    argv: tuple[str, ...]
    """Arguments after ``arboretum``."""
    outputs: tuple[str, ...] = field(default=())
    """Files (relative to OUT) the stage must produce."""


def stages(out: Path, seed: int) -> list[Stage]:
    """The demo, in order. Paths are relative to ``out``."""
    real = str(asset_path("scans", "06_adtree_tree7", "06_adtree_tree7.xyz"))
    return [
        Stage("inspect a bundled real scan", ("scan", "info", real, "--json")),
        Stage(
            "synthesise a leaf-on tree with ground truth",
            ("synth", "--model", "guiding", "--species", "default", "--seed", str(seed), "--points", "12000",
             "--out", "synth_scan.ply", "--truth", "synth_truth.npz", "--json"),
            ("synth_scan.ply", "synth_truth.npz"),
        ),
        Stage(
            "decompose it into HBL examples",
            ("decompose", "synth_scan.ply", "--library", "library", "--save-hbl", "synth_hbl.npz", "--seed",
             str(seed), "--json"),
            ("synth_hbl.npz",),
        ),
        Stage(
            "decompose the real scan into the same library",
            ("decompose", real, "--library", "library", "--save-hbl", "real_hbl.npz", "--json"),
            ("real_hbl.npz",),
        ),
        Stage("list the library", ("library", "info", "library", "--json")),
        Stage(
            "grow twigs and leaves, export GLB and skeleton",
            ("grow", "synth_hbl.npz", "--out", "tree.glb", "--skeleton", "tree_skeleton.json", "--seed", str(seed),
             "--json"),
            ("tree.glb", "tree_skeleton.json"),
        ),
        Stage("picture: the scan", ("render", "synth_scan.ply", "--out", "1_scan.png", "--json"), ("1_scan.png",)),
        Stage("picture: the HBL", ("render", "synth_hbl.npz", "--out", "2_hbl.png", "--json"), ("2_hbl.png",)),
        Stage("picture: the grown tree", ("render", "tree.glb", "--out", "3_tree.png", "--json"), ("3_tree.png",)),
    ]


def run_stage(stage: Stage, out: Path, index: int, total: int) -> dict:
    """Run one stage in ``out``; raise ``ArboretumError`` with its stderr when it fails."""
    argv = [sys.executable, "-m", "arboretum_library.cli", *stage.argv]
    print(f"[{index}/{total}] {stage.name}: arboretum {shlex.join(stage.argv)}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(argv, cwd=out, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        detail = proc.stderr.strip().splitlines()[-1:] or ["(no message)"]
        raise ArboretumError(f"demo stage '{stage.name}' failed (exit {proc.returncode}): {detail[0]}")
    missing = [o for o in stage.outputs if not (out / o).is_file()]
    if missing:
        raise ArboretumError(f"demo stage '{stage.name}' did not write {', '.join(missing)}")
    try:
        result = json.loads(proc.stdout) if proc.stdout.strip() else None
    except json.JSONDecodeError:
        result = proc.stdout.strip()
    print(f"      done in {seconds:.2f} s", file=sys.stderr, flush=True)
    return {"stage": stage.name, "argv": list(stage.argv), "seconds": round(seconds, 3), "result": result}


def run(args: argparse.Namespace) -> int:
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    plan = stages(out, args.seed)
    t0 = time.perf_counter()
    report = [run_stage(s, out, i + 1, len(plan)) for i, s in enumerate(plan)]
    summary = {"out": str(out), "seconds": round(time.perf_counter() - t0, 2), "stages": report}
    (out / "demo.json").write_text(json.dumps(summary, indent=2) + "\n")
    lines = [f"{r['seconds']:7.2f} s  {r['stage']}" for r in report]
    emit(args, summary, "\n".join(lines) + f"\ndemo finished in {summary['seconds']} s; everything is in {out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the whole pipeline on bundled data into a folder")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--seed", type=int, default=7, help="seed for every stochastic stage (default: 7)")
    add_json_flag(p)
    p.set_defaults(func=run)
