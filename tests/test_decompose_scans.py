"""Decomposition of the bundled real scans and of harmonic-model trees of the six Table 2 species (slow)."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.model import Level
from arboretum_server.decompose.options import SPECIES_COUNTS
from arboretum_server.decompose.report import real_figures, synth_figures

pytestmark = pytest.mark.slow


def _scan(scans_dir, prefix):
    found = sorted(scans_dir.glob(f"{prefix}*/*.xyz"))
    if not found:
        pytest.skip(f"scan {prefix} is not bundled")
    return found[0]


@pytest.mark.parametrize("prefix", ["01_", "06_", "10_"])
def test_leaf_off_scans_give_connected_skeletons(scans_dir, prefix):
    f = real_figures(_scan(scans_dir, prefix))
    assert f["connected"] and f["main_branches"] == 8 and f["lobes"] == 40
    assert f["crossings"] == 0  # the pine (10) kept 1 until lobes wrapped round its trunk were carved
    assert f["time_s"] < 5.0
    # smoothed branches: the graph paths turned 0.22-0.54 rad per vertex (mains) and 0.33-0.98 (secondaries)
    assert f["main_turning"] < 0.15 and f["secondary_turning"] < 0.2
    # no main branch climbs one limb and comes down to reach another: 06's trunk fell 0.23 of the height
    # before hooked paths were routed across scan gaps (now 0.038, a drooping limb; 01 0.023, 10 0.041)
    assert f["main_drop"] <= 0.05


def test_coffeetree_main_branches_follow_the_qsm(scans_dir):
    f = real_figures(_scan(scans_dir, "01_"))
    assert f["foliage_source"] == "crown"  # leaf-off: nearly all wood
    assert f["leaf_points"] / f["points"] < 0.1
    # trunk and first-order branches: 0.0134 (0.0119 with reach-only main selection, 0.0101 unsmoothed)
    assert f["qsm_order01_ref_to_main"] <= 0.015
    assert f["qsm_main_to_ref"] <= 0.01  # no invented main branches


def test_leaf_on_scan_lobes_cover_the_crown(scans_dir):
    f = real_figures(_scan(scans_dir, "07_"))
    assert f["foliage_source"] == "leaf" and f["leaf_cover"] >= 0.95
    assert f["qsm_order01_ref_to_main"] <= 0.02
    assert f["main_turning"] < 0.15 and f["secondary_turning"] < 0.2  # unsmoothed: 0.47 and 0.84
    # the bare trunk is wood: no lobe along it (12 of 40 lobe centres sat below 0.6 of the height before)
    assert f["crown_base"] > 0.8 and f["lobes_below_crown_base"] <= 8
    # secondaries straightened to keep out of foreign lobes follow less of the wood: 0.79 measured then,
    # 0.91 now
    assert f["qsm_ref_covered_all"] >= 0.85


@pytest.mark.parametrize("species", sorted(SPECIES_COUNTS))
@pytest.mark.parametrize("case", ["leaf-on", "leaf-off", "sector"])
def test_harmonic_species_hold_the_floor(species, case):
    f = synth_figures(species, 1, case)
    assert f["counts_ok"] and f["connected"] and f["main_turning"] < 0.15
    assert f["crossings"] == 0  # 0 in all 72 measured (20 in seed 1 before the bent repair, 8 before unwrap)
    assert f["leaf_cover"] >= 0.98
    # dense pine whorls and missing data are the hard cases; the rest holds 3 % of height
    assert f["main_fit"] <= (0.06 if species == "pine" or case == "sector" else 0.03)
    # the 2 % over what the scan shows, equally long branches interchangeable (evaluate.py)
    assert f["main_fit_seen"] <= 0.02  # pine 0.007-0.014 (0.025-0.041 before spread-only selection for it)
    assert f["main_precision"] <= 0.01  # the main branches found lie on real wood


def test_level_structure_of_a_real_scan(scans_dir):
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose

    d = decompose(np.loadtxt(_scan(scans_dir, "06_")), DecomposeOptions(species="walnut"))
    hbl = d.hbl
    assert hbl.by_level(Level.MAIN) == list(range(10)) and len(hbl.lobes) == 46
    assert all(hbl.branches[i].parent < 10 for i in hbl.by_level(Level.SECONDARY))


@pytest.mark.parametrize("species", sorted(SPECIES_COUNTS))
@pytest.mark.parametrize("case", ["leaf-on", "leaf-on+labels", "leaf-off", "sector"])
def test_virtual_scanner_harmonic_species(species, case):
    f = synth_figures(species, 1, case, scanner=True)
    assert f["counts_ok"] and f["connected"]
    assert f["leaf_cover"] >= 0.95
    assert f["crossings"] == 0
    assert f["main_fit"] <= (0.06 if species == "pine" or case == "sector" else 0.03)
    # pine 0.013-0.020 (0.025-0.029 before "seen" was measured from the branch surface, 0.058 before
    # the spread term in main selection); cherry sector 0.023
    assert f["main_fit_seen"] <= (0.025 if species == "pine" or case == "sector" else 0.02)
    assert f["main_precision"] <= 0.01


@pytest.mark.parametrize("preset", ["default", "elm", "upward"])
@pytest.mark.parametrize("case", ["leaf-on", "leaf-off"])
def test_virtual_scanner_guiding_presets(preset, case):
    f = synth_figures(preset, 1, case, scanner=True, model="guiding")
    assert f["counts_ok"] and f["connected"] and f["leaf_cover"] >= 0.95 and f["crossings"] == 0
    assert f["main_fit"] <= 0.08  # guiding-vector trees: see docs/decomposition.md, Limitations
    assert f["main_fit_seen"] <= 0.06 and f["main_precision"] <= 0.012


@pytest.mark.parametrize(("species", "seed", "case"), [("pine", 3, "leaf-off"), ("pine", 1, "leaf-on")])
def test_refinements_of_a_pine_cross_no_lobe(species, seed, case):
    # Every other lobe: insert its outer third (by distance from the axis) as a new lobe, merge it with
    # its nearest neighbour, split it in two. Before the lobe losing points was rebuilt, kept branches
    # running through new lobes were routed again and buried centres freed, 19 inserts, 19 merges and
    # 9 splits of 85 each (these two pines, an apple and a cherry) crossed a lobe; then 1, 0 and 1, all
    # lobe 6 of the leaf-on pine, whose outer part lies behind the rest of the lobe (session 7:
    # tunnel.behind); now none.
    from arboretum_server.decompose.evaluate import crossings
    from arboretum_server.decompose.options import DecomposeOptions
    from arboretum_server.decompose.pipeline import decompose
    from arboretum_server.decompose.refine import insert_lobe, merge_lobes, split_lobe
    from arboretum_server.decompose.report import CASES, grow_truth
    from arboretum_server.decompose.toytree import toy_scan

    truth = grow_truth("harmonic", species, seed)
    pts, _ = toy_scan(truth, n=40000, noise=0.002 * float(np.ptp(truth.positions[:, 2])), seed=seed, **CASES[case])
    d = decompose(pts, DecomposeOptions(species=species))
    centres = np.array([lb.centre for lb in d.lobes])
    bad = []
    for j in range(0, len(d.lobes), 2):
        m = d.lobes[j].members
        r = np.linalg.norm(d.points[m][:, :2], axis=1)
        k = int(np.argsort(np.linalg.norm(centres - centres[j], axis=1))[1])
        p = d.points[m]
        t = (p - p.mean(axis=0)) @ np.linalg.svd(p - p.mean(axis=0))[2][0]
        strokes = [d.to_output(p[t < 0][:5]), d.to_output(p[t >= 0][:5])]
        for name, out in (("insert", insert_lobe(d, m[r >= np.quantile(r, 0.67)])),
                          ("merge", merge_lobes(d, [j, k])), ("split", split_lobe(d, j, strokes))):
            if crossings(out.hbl):
                bad.append((name, j))
    assert bad == []
