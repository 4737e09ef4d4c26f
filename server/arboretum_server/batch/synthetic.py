"""Sets of synthetic scans to try and measure a library build on (tests, ``bench_batch``).

Each scan is a harmonic-model tree (``synth.harmonic.grow_species``) sampled by the virtual scanner
(``synth.scanner.scan``) and written as a labelled PLY named ``SPECIES_SEED.ply``, so the build's
species-from-file-name rule picks its species up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

SPECIES_CYCLE = ("apple", "cherry", "ginkgo", "walnut")
"""Species used in turn (all in VRTree Table 2)."""


def synthetic_scan(folder: Path, species: str, seed: int, points: int = 4000) -> Path:
    """Write one labelled virtual scan ``folder/SPECIES_SEED.ply`` (seeded, so reproducible)."""
    from arboretum_library.pointio import write_points
    from arboretum_server.synth.harmonic import grow_species
    from arboretum_server.synth.scanner import ScanOptions, scan

    truth = grow_species(species, seed)
    s = scan(truth, ScanOptions(points=points), np.random.default_rng(seed))
    return write_points(Path(folder) / f"{species}_{seed:03d}.ply", s.points, labels=s.labels)


def synthetic_scans(folder: Path, count: int, points: int = 4000, first_seed: int = 1) -> list[Path]:
    """``count`` scans cycling through ``SPECIES_CYCLE`` with seeds from ``first_seed``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return [synthetic_scan(folder, SPECIES_CYCLE[i % len(SPECIES_CYCLE)], first_seed + i, points)
            for i in range(count)]
