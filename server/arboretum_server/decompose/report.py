"""Accuracy figures for docs/decomposition.md: ``python -m arboretum_server.decompose.report [real|synth]``.

real:  the bundled scans; TreeQSM references (01, 07) compared with skeleton_fit-style figures.
synth: harmonic-model trees of the six Table 2 species (arboretum_server.synth) sampled by
       ``toytree.toy_scan`` (cylinder surfaces + leaf cards; leaf-on, leaf-on with labels, leaf-off,
       a 69-degree missing sector), scored by ``evaluate.evaluate``.
scanner: the same trees and cases through the shared virtual scanner (``synth.scanner``: 4 stations,
       occlusion, range noise; 40,000 points; the sector is 70 degrees), plus guiding-vector presets.
Prints one JSON object per line. ``synth`` and ``scanner`` take seeds after the word (default 1):
``python -m arboretum_server.decompose.report synth 1 2 3``.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from arboretum_library.model import LEAF, Level

from .evaluate import (
    connected,
    crossings,
    evaluate,
    lobe_distance,
    main_drop,
    mean_turning,
    reference_fit,
)
from .options import SPECIES_COUNTS, DecomposeOptions
from .pipeline import decompose
from .toytree import toy_scan

CASES = {"leaf-on": {}, "leaf-on+labels": {}, "leaf-off": {"leaf_fraction": 0.0}, "sector": {"missing_sector": 1.2}}


def read_qsm(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts (C, 3), ends (C, 3), branch order (C,)) of a TreeQSM cylinder CSV."""
    rows = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    col = {h: i for i, h in enumerate(rows[0].strip().split(","))}
    data = np.array([[float(x) for x in r.split(",")] for r in rows[1:] if r.strip()])
    s = data[:, [col["start_x"], col["start_y"], col["start_z"]]]
    a = data[:, [col["axis_x"], col["axis_y"], col["axis_z"]]]
    return s, s + a * data[:, [col["length"]]], data[:, col["BranchOrder"]]


def lobes_below_crown_base(hbl) -> tuple[float, int]:
    """(crown base as a fraction of the height: the lowest main branch leaving the trunk, number of lobe
    centres below it)."""
    forks = [b.points[0, 2] for b in hbl.branches if b.level == Level.MAIN and b.parent == 0]
    base = (min(forks) if forks else hbl.branches[0].points[-1, 2]) - hbl.root[2]
    z = np.array([lb.centre[2] for lb in hbl.lobes]) - hbl.root[2]
    return base / max(hbl.height, 1e-12), int((z < base).sum())


def real_figures(scan: Path) -> dict:
    d = decompose(np.loadtxt(scan)[:, :3], DecomposeOptions())

    def to(p):
        return d.to_output((p - d.root_scan) * d.scale)

    leaf = d.hbl.points[d.labels == LEAF]
    out = {"scan": scan.name, "time_s": round(sum(d.timing.values()), 3), **d.stats,
           "connected": connected(d.hbl), "crossings": crossings(d.hbl),
           "main_turning": round(mean_turning(d.hbl, Level.MAIN), 4), "main_drop": round(main_drop(d.hbl), 4),
           "secondary_turning": round(mean_turning(d.hbl, Level.SECONDARY), 4),
           "crown_base": round(lobes_below_crown_base(d.hbl)[0], 3), "lobes_below_crown_base": lobes_below_crown_base(d.hbl)[1],
           "leaf_cover": round(float((lobe_distance(d.hbl, leaf) <= 0.01).mean()), 4) if len(leaf) else None}
    qsm = sorted(scan.parent.glob("*cylinders.csv"))
    if qsm:
        s, e, order = read_qsm(qsm[0])
        low = order <= 1
        out["qsm"] = qsm[0].name
        out.update({f"qsm_{k}": round(v, 4) for k, v in reference_fit(d.hbl, to(s), to(e)).items()})
        out.update({f"qsm_order01_{k}": round(v, 4) for k, v in reference_fit(d.hbl, to(s[low]), to(e[low])).items()})
    return out


def grow_truth(model: str, species: str, seed: int):
    """The sweeps' ground truth: a guiding-vector preset (``model`` 'guiding') or a harmonic species."""
    if model == "guiding":
        from arboretum_server.synth.guiding import grow_guiding
        from arboretum_server.synth.presets import preset

        return grow_guiding(preset(species), seed, species)
    from arboretum_server.synth.harmonic import grow_species

    return grow_species(species, seed)


def virtual_scan(truth, case: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(points, labels) of the sweeps' virtual-scanner scan of ``truth``: 40,000 points, leaf-off, or a
    70-degree missing sector, by ``case``."""
    from arboretum_server.synth.scanner import ScanOptions, scan

    opts = ScanOptions(points=40000, leaf_off=case == "leaf-off", missing_sector=70.0 if case == "sector" else 0.0)
    s = scan(truth, opts, np.random.default_rng(seed))
    return s.points, s.labels


def synth_figures(species: str, seed: int, case: str, scanner: bool = False, model: str = "harmonic") -> dict:
    truth = grow_truth(model, species, seed)
    o = DecomposeOptions(species=species)
    if scanner:
        pts, lab = virtual_scan(truth, case, seed)
    else:
        pts, lab = toy_scan(truth, n=40000, noise=0.002 * float(np.ptp(truth.positions[:, 2])), seed=seed,
                            **CASES[case])
    d = decompose(pts, o, labels=lab if case.endswith("labels") else None)

    def to(p):
        return d.to_output((p - d.root_scan) * d.scale)

    m = evaluate(d.hbl, truth, pts[lab == LEAF], to, *o.counts(), scan_points=pts)
    return {"model": model, "scanner": scanner, "species": species, "seed": seed, "case": case, "time_s": round(sum(d.timing.values()), 3),
            **{k: round(v, 4) if isinstance(v, float) else v for k, v in m.as_dict().items()}}


def main(argv: list[str]) -> int:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    what = argv[0] if argv else "real"
    if what == "real":
        from arboretum_library.assets import sample_scans

        for scan in sample_scans():
            print(json.dumps(real_figures(scan)), flush=True)
    else:
        scanner = what == "scanner"
        seeds = [int(a) for a in argv[1:]] or [1]
        runs = [("harmonic", s) for s in SPECIES_COUNTS]
        if scanner:
            runs += [("guiding", s) for s in ("default", "elm", "upward")]
        for seed in seeds:
            for model, species in runs:
                for case in CASES:
                    print(json.dumps(synth_figures(species, seed, case, scanner, model)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
