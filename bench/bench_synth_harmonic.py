"""Speed of the harmonic species model (issue 3).

The paper grows a paper birch of 15,146 particles in 2.4 s; the target is under 0.5 s for a comparable
particle count. We grow the pine preset aged to A = 80 (seed 1: 15,428 particles), median of 5 runs.
Baseline, measured in the same run: equation 1 (B R W H) evaluated one bud at a time, as a per-particle
Python loop would, over the same particles (the orientation update alone, so it understates a naive
model's total time).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from arboretum_server.synth.harmonic import SPECIES, grow_species
from arboretum_server.synth.harmonic_growth import _Buds, _Tables, _turn
from arboretum_server.synth.species import SpeciesParams

from .harness import Row, median_time

SEED = 1
AGE = 80


def bench_species() -> SpeciesParams:
    """The pine preset grown to age ``AGE`` with a trunk as long."""
    pine = SPECIES["pine"]
    trunk = dataclasses.replace(pine.levels[0], length=AGE)
    return dataclasses.replace(pine, max_age=AGE, levels=(trunk, *pine.levels[1:]))


def _per_bud_turns(sp: SpeciesParams, level: np.ndarray, age: np.ndarray) -> float:
    """Seconds to evaluate equation 1 for each (level, age) bud separately."""
    t = _Tables(sp)
    rng = np.random.default_rng(0)
    phase = np.zeros((1, t.harm_f.shape[1]))
    q = np.array([[1.0, 0.0, 0.0, 0.0]])
    t0 = time.perf_counter()
    for lv, a in zip(level.tolist(), age.tolist()):
        bud = _Buds(q=q, last=np.array([0]), level=np.array([lv]), branch=np.array([0]),
                    age=np.array([a]), term=np.array([a + 1]), phase=phase)
        _turn(bud, t, rng)
    return time.perf_counter() - t0


def run() -> list[Row]:
    sp = bench_species()
    tree = grow_species(sp, SEED)
    n = tree.node_count
    fast = median_time(lambda: grow_species(sp, SEED), runs=5, warmup=1)
    first = np.r_[True, tree.branch_id[1:] != tree.branch_id[tree.parent[1:]]]
    age = np.zeros(n, np.int64)
    for i in range(1, n):  # age along the branch (only for the baseline's inputs)
        age[i] = 0 if first[i] else age[tree.parent[i]] + 1
    slow = _per_bud_turns(sp, tree.branch_order, age)
    presets = median_time(lambda: [grow_species(name, SEED) for name in SPECIES], runs=3, warmup=1)
    return [
        Row(name=f"harmonic pine A={AGE} ({n:,} particles)", median=fast, target=0.5, runs=5,
            baseline="eq. 1 per bud in a Python loop (orientation only)", ratio=fast / slow,
            note=f"paper: 15,146 particles in 2.4 s; baseline {slow:.2f} s",
            extra={"particles": n, "leaves": tree.leaf_count, "baseline_s": slow}),
        Row(name=f"harmonic all {len(SPECIES)} presets, seed {SEED}", median=presets, runs=3),
    ]
