"""The decomposition end to end on a toy tree with ground truth; bad input; examples; refinement; CLI."""

from __future__ import annotations

import hashlib
import json
import re

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.model import HBL, LEAF, WOOD, Level
from arboretum_server.decompose import refine
from arboretum_server.decompose.evaluate import connected, crossings, evaluate
from arboretum_server.decompose.examples import (
    counter_ids,
    make_examples,
    provenance,
    split_structures,
)
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from arboretum_server.decompose.toytree import toy_scan, toy_truth
from factories import stubbed_pole

N_M, N_L = 6, 20
OPTS = DecomposeOptions(n_main=N_M, n_lobes=N_L)


@pytest.fixture(scope="module")
def truth():
    return toy_truth()


@pytest.fixture(scope="module")
def leaf_on(truth):
    pts, lab = toy_scan(truth)
    return pts, lab, decompose(pts, OPTS)


def _metrics(d, truth, pts, lab):
    def to_frame(p):
        return d.to_output((p - d.root_scan) * d.scale)

    return evaluate(d.hbl, truth, pts[lab == LEAF], to_frame, N_M, N_L, scan_points=pts)


def test_leaf_on_meets_the_accuracy_floor(truth, leaf_on):
    pts, lab, d = leaf_on
    m = _metrics(d, truth, pts, lab)
    assert m.counts_ok and m.connected
    assert m.main_fit <= 0.02 and m.main_fit_worst <= 0.03
    assert m.main_fit_seen <= 0.02 and m.main_precision <= 0.01
    assert m.leaf_cover >= 0.93
    assert m.crossings <= 1
    assert d.hbl.height == pytest.approx(0.8, abs=0.05)
    assert all((b.radii > 0).all() for b in d.hbl.branches)


def test_leaf_on_with_given_labels(truth):
    pts, lab = toy_scan(truth, seed=1)
    d = decompose(pts, OPTS, labels=lab)
    m = _metrics(d, truth, pts, lab)
    assert np.array_equal(d.labels, lab[d.source_index])
    assert m.counts_ok and m.connected and m.crossings == 0
    assert m.main_fit <= 0.02 and m.leaf_cover >= 0.99


def test_leaf_off_is_nearly_all_wood_and_meets_counts(truth):
    pts, lab = toy_scan(truth, leaf_fraction=0.0, seed=2)
    d = decompose(pts, OPTS)
    assert (d.labels == WOOD).mean() >= 0.9
    assert d.stats["foliage_source"] == "crown"
    m = _metrics(d, truth, pts, lab)
    assert m.counts_ok and m.connected and m.main_fit <= 0.02 and m.crossings <= 1


def test_missing_sector_still_connects(truth):
    pts, lab = toy_scan(truth, missing_sector=1.2, seed=3)
    d = decompose(pts, OPTS)
    m = _metrics(d, truth, pts, lab)
    assert m.counts_ok and m.connected
    assert m.main_fit <= 0.03 and m.leaf_cover >= 0.9


def test_child_never_thicker_than_parent_and_topological_order(leaf_on):
    hbl = leaf_on[2].hbl
    assert hbl.by_level(Level.MAIN) == list(range(N_M))
    for i, b in enumerate(hbl.branches):
        assert b.parent < i
        if b.parent >= 0:
            assert b.radii[0] <= hbl.branches[b.parent].radii[b.parent_vertex] + 1e-12
            if b.level == Level.SECONDARY:
                assert hbl.branches[b.parent].level == Level.MAIN
    assert sorted(lb.branch for lb in hbl.lobes) == list(range(N_M, N_M + N_L))


def test_every_lobe_hull_is_a_closed_manifold(leaf_on):
    from arboretum_server.decompose.lobes import is_closed_manifold

    assert all(is_closed_manifold(lb.hull_faces) for lb in leaf_on[2].hbl.lobes)


def test_same_seed_same_result(truth):
    pts, _ = toy_scan(truth, n=8000, seed=4)
    a, b = decompose(pts, OPTS), decompose(pts, OPTS)
    assert len(a.hbl.branches) == len(b.hbl.branches)
    for x, y in zip(a.hbl.branches, b.hbl.branches):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.radii, y.radii)
    for x, y in zip(a.hbl.lobes, b.hbl.lobes):
        assert np.array_equal(x.hull_vertices, y.hull_vertices)


@pytest.mark.parametrize("slope", [0.0, 0.1, 0.2])
def test_ground_is_removed_flat_or_sloped(truth, slope):
    # a ground disc 4 m round the trunk, rising `slope` along x through the trunk base (the tree is
    # about 8 m tall). Until session 6 only a flat disc was found: a 5 % slope was refused as "no trunk
    # base" and a 10-20 % one put the root on the disc's downhill rim, 0.5 of the height away
    pts, _ = toy_scan(truth, leaf_fraction=0.0, seed=5)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-4, 4, (6000, 2))
    ground = np.c_[xy, pts[:, 2].min() + slope * xy[:, 0] + rng.uniform(-0.05, 0.05, 6000)]
    d = decompose(np.r_[pts, ground], OPTS)
    assert 5500 <= d.stats["ground_removed"] <= 6000 + 0.05 * len(pts)
    assert np.linalg.norm(d.root_scan[:2]) < 0.2


def test_two_trees_up_a_slope_are_refused(truth):
    # the second tree stands 0.4 of the height up a 12 % slope, its foot 4.8 % of the height above the
    # first's: the base band, measured from the lowest point, never held it (decomposed as one tree);
    # measured from the ground plane it holds both feet
    pts, _ = toy_scan(truth, leaf_fraction=0.0, seed=5)
    z0, h = pts[:, 2].min(), np.ptp(pts[:, 2])
    rng = np.random.default_rng(1)
    xy = rng.uniform(-4, 4 + 0.4 * h, (8000, 2))
    ground = np.c_[xy, z0 + 0.12 * xy[:, 0] + rng.uniform(-0.05, 0.05, 8000)]
    second = pts + [0.4 * h, 0.0, 0.12 * 0.4 * h]
    with pytest.raises(InputError, match="2 separate trunks"):
        decompose(np.r_[pts, second, ground], OPTS)


def test_ground_that_is_not_one_plane_is_named(truth):
    # a ridge, falling 40 % both ways from the trunk: no plane or gentle curve fits, and the lowest 3 % of
    # the cloud is two strips of ground, which were refused as "2 separate trunks" (a 15-25 % ridge is cut
    # as curved ground since session 18, tests/test_ground_s18_curved.py, and a 30 % one, followed down
    # its walls, since session 19, tests/test_ground_s19_understory.py)
    pts, _ = toy_scan(truth, leaf_fraction=0.0, seed=5)
    xy = np.random.default_rng(0).uniform(-4, 4, (6000, 2))
    ridge = np.c_[xy, pts[:, 2].min() - 0.4 * np.abs(xy[:, 0])]
    with pytest.raises(InputError, match="flat patches .* not trunks: ground that is not one plane"):
        decompose(np.r_[pts, ridge], OPTS)


def test_a_cloud_far_wider_than_tall_is_one_clear_error():
    # 2 km across, 1e-17 high: the ground search's column keys (2 % of the height wide) overflowed
    # int64, a FloatingPointError under the tests' error settings
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-1e3, 1e3, (3000, 2)), rng.uniform(0, 1e-17, 3000)]
    with pytest.raises(InputError, match="no trunk base"):
        decompose(pts, OPTS)


def test_no_ground_no_points_removed(truth, leaf_on):
    # the crown's underside holds planes too (the lowest point of each column under it): a plane
    # with the trunk below it is no ground
    assert leaf_on[2].stats["ground_removed"] == 0
    assert decompose(toy_scan(truth, leaf_fraction=0.0, seed=5)[0], OPTS).stats["ground_removed"] == 0


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda t: np.zeros((50, 3)) + np.arange(50)[:, None], "usable points"),
        (lambda t: np.full((500, 3), np.nan), "usable points"),
        (lambda t: np.c_[np.random.default_rng(0).normal(size=(500, 2)), np.zeros(500)], "one height"),
        (lambda t: np.r_[toy_scan(t, 6000)[0], toy_scan(t, 6000)[0] + [9, 0, 0]], "separate trunks"),
        (lambda t: np.random.default_rng(0).normal(size=(3000, 3)), "no trunk base"),
        # a flat plane with a little noise: its lowest 3 % holds 1 point, which read as a trunk base
        # (and the 'tree' then took 245 s to decompose)
        (lambda t: np.c_[np.random.default_rng(0).uniform(-1, 1, (800, 2)),
                         np.random.default_rng(1).normal(0, 0.002, 800)], "no trunk base"),
        (lambda t: np.ones((500, 2)), r"expected an \(N, 3\)"),
        # a tree scaled by 1e200 (a file read in the wrong format): a ValueError from scipy's distances
        (lambda t: toy_scan(t, 3000)[0] * 1e200, "coordinates up to .* wrong format or units"),
    ],
)
def test_bad_input_raises_one_clear_input_error(truth, make, words):
    with pytest.raises(InputError, match=words):
        decompose(make(truth), OPTS)


def test_a_branch_hanging_into_the_base_band_is_no_second_tree(truth):
    # a weeping branch's leaves reach into the lowest 3 % of the cloud, 0.3 of the height from the trunk
    # (the guiding elm through the virtual scanner, with 24,000 points or more, was refused as 2 trees)
    pts = toy_scan(truth, 6000)[0]
    z = pts[:, 2]
    h, band = np.ptp(z), z < z.min() + 0.03 * np.ptp(z)
    rng = np.random.default_rng(3)
    n = max(10, band.sum() // 5)  # a big cluster of the band, under half the trunk's points per metre
    centre = np.median(pts[band, :2], axis=0) + [0.3 * h, 0.0]
    clump = np.c_[centre + rng.normal(0, 0.003 * h, (n, 2)), z.min() + rng.uniform(0.015, 0.029, n) * h]
    plain, hanging = decompose(pts, OPTS), decompose(np.vstack([pts, clump]), OPTS)
    np.testing.assert_allclose(hanging.root_scan, plain.root_scan)
    assert len(hanging.hbl.by_level(Level.MAIN)) == N_M
    # a stem standing on the ground there is a second tree
    stem = np.c_[centre + rng.normal(0, 0.003 * h, (6 * n, 2)), z.min() + rng.uniform(0.0, 0.1, 6 * n) * h]
    with pytest.raises(InputError, match="2 separate trunks"):
        decompose(np.vstack([pts, stem]), OPTS)
    # so is the tree's twin 2 % of the height up a slope (only its lowest 1 % lies in the band), and
    # one stray point under the first tree does not make the twin hang
    twin = pts + [0.3 * h, 0.0, 0.02 * h]
    stray = pts[np.argmin(z)] - [0.0, 0.0, 0.012 * h]
    for cloud in (np.vstack([pts, twin]), np.vstack([pts, pts + [0.3 * h, 0.0, 0.005 * h], stray])):
        with pytest.raises(InputError, match="2 separate trunks"):
            decompose(cloud, OPTS)


def test_a_second_tree_standing_higher_is_named_in_a_note(truth, tmp_path, capsys):
    # the tree's twin 0.3 of the height away with its foot 5 % of the height higher and no ground
    # scanned: it never enters the base band (the probe: 135 of 135 such pairs decomposed without a
    # word). The decomposition goes on, as before, but names the column it found
    from arboretum_library.cli import main

    pts = toy_scan(truth, 6000)[0]
    h = np.ptp(pts[:, 2])
    twin = decompose(np.vstack([pts, pts + [0.3 * h, 0.0, 0.05 * h]]), OPTS)
    (col,) = twin.stats["trunk_columns"]
    dist, rise, foot = col["distance"], col["rise"], np.array(col["foot"])
    assert abs(dist / h - 0.3) < 0.03 and abs(rise / h - 0.05) < 0.015
    base = pts[np.argmin(pts[:, 2])] + [0.3 * h, 0.0, 0.05 * h]  # the twin's lowest point
    assert np.linalg.norm(foot[:2] - base[:2]) < 0.05 * h and abs(foot[2] - base[2]) < 0.015 * h
    assert decompose(pts, OPTS).stats["trunk_columns"] == []
    # a wide clump of leaves hanging there, or a thin twig, is no trunk column; a dense stem is one
    rng = np.random.default_rng(3)
    foot = np.median(pts[pts[:, 2] < pts[:, 2].min() + 0.03 * h, :2], axis=0) + [0.3 * h, 0.0]
    for spread, n, found in ((0.02, 150, 0), (0.003, 40, 0), (0.003, 150, 1)):
        stem = np.c_[foot + rng.normal(0, spread * h, (n, 2)), pts[:, 2].min() + rng.uniform(0.05, 0.15, n) * h]
        assert len(decompose(np.vstack([pts, stem]), OPTS).stats["trunk_columns"]) == found
    scan = tmp_path / "two.xyz"
    np.savetxt(scan, np.vstack([pts, pts + [0.3 * h, 0.0, 0.05 * h]]))
    assert main(["decompose", str(scan), "--up", "z", "--main", str(N_M), "--lobes", str(N_L)]) == 0
    out = capsys.readouterr().out
    got = re.search(r"note: 1 trunk-like column away from the trunk base \(foot at x (\S+), y (\S+), (\S+) from "
                    r"the trunk base and (\S+) higher; scan units, Z up\): another tree\?", out)
    assert got and np.allclose([float(v) for v in got.groups()], [*foot[:2], dist, rise], atol=0.02 * h)


def test_weeping_leaves_on_the_ground_are_no_second_trunk(truth):
    # a weeping branch's leaves reach the ground 0.3 of the height from the trunk, their lowest point
    # only 0.4 % of the height above the trunk's (too low to hang by STANDING), spreading wider as
    # they rise (2 m out per metre up): no trunk column rises from them. The guiding elm on a ground
    # disc was refused as "2 separate trunks" in 8 of its 15 probe clouds, 2 now
    pts = toy_scan(truth, 6000)[0]
    z = pts[:, 2]
    h, band = np.ptp(z), z < z.min() + 0.03 * np.ptp(z)
    rng = np.random.default_rng(3)
    centre = np.median(pts[band, :2], axis=0) + [0.3 * h, 0.0]
    t = rng.uniform(0.004, 0.12, 100) * h
    leaves = np.c_[centre + rng.normal(0, 1, (100, 2)) * (0.003 * h + 2 * (t - t.min()))[:, None], z.min() + t]
    plain, weeping = decompose(pts, OPTS), decompose(np.vstack([pts, leaves]), OPTS)
    np.testing.assert_allclose(weeping.root_scan, plain.root_scan)
    # so do three times as many, more in the band than the trunk holds: the largest cluster may hang,
    # the lowest may not (a reviewer's case: 'the largest never hangs' refused this as two trees)
    t3 = rng.uniform(0.004, 0.12, 300) * h
    heavy = np.c_[centre + rng.normal(0, 1, (300, 2)) * (0.003 * h + 2 * (t3 - t3.min()))[:, None], z.min() + t3]
    assert (heavy[:, 2] < z.min() + 0.03 * h).sum() > band.sum()
    np.testing.assert_allclose(decompose(np.vstack([pts, heavy]), OPTS).root_scan, plain.root_scan)
    # the same points standing as a column are a trunk
    stem = np.c_[centre + rng.normal(0, 0.005 * h, (100, 2)), z.min() + t]
    with pytest.raises(InputError, match="2 separate trunks"):
        decompose(np.vstack([pts, stem]), OPTS)
    # the largest cluster never hangs: a trunk with an occlusion gap and a bush beside it is gappy and
    # not narrow, and hanging it put the root on the stem without a word (a reviewer's case)
    c0 = np.median(pts[band, :2], axis=0)
    r = np.linalg.norm(pts[:, :2] - c0, axis=1)
    occluded = pts[~((r < 0.3) & (z > z.min() + 0.34) & (z < z.min() + 0.51))]
    ang, rad = rng.uniform(-0.6, 0.6, 150), rng.uniform(0.3, 0.5, 150)
    bush = np.c_[c0 + np.c_[np.cos(ang), np.sin(ang)] * rad[:, None], z.min() + rng.uniform(0.3, 0.85, 150)]
    with pytest.raises(InputError, match="2 separate trunks"):
        decompose(np.vstack([occluded, bush, stem]), OPTS)
    # nor when the stem is denser in the band than the trunk (a reviewer's case against a rule tried in
    # session 8, which let the lowest cluster hang beside a larger column: the root went to the stem)
    dense = np.c_[centre + rng.normal(0, 0.005 * h, (600, 2)), z.min() + rng.uniform(0.004, 0.12, 600) * h]
    with pytest.raises(InputError, match="2 separate trunks"):
        decompose(np.vstack([occluded, bush, dense]), OPTS)


def test_label_length_mismatch_is_an_input_error(truth):
    pts, lab = toy_scan(truth, n=3000)
    with pytest.raises(InputError, match="labels"):
        decompose(pts, OPTS, labels=lab[:-1])


@pytest.mark.parametrize("label", [LEAF, WOOD])
def test_all_leaf_or_all_wood_labels_give_a_best_effort(truth, label):
    pts, _ = toy_scan(truth, n=6000, seed=6)
    d = decompose(pts, OPTS, labels=np.full(len(pts), label, np.uint8))
    assert len(d.hbl.lobes) == N_L and len(d.hbl.by_level(Level.MAIN)) == N_M and connected(d.hbl)
    assert d.stats["foliage_source"] == ("leaf" if label == LEAF else "crown")


def test_examples_split_one_per_main_branch(leaf_on, tmp_path):
    d = leaf_on[2]
    src = tmp_path / "tree.xyz"
    src.write_bytes(b"1 2 3\n")
    prov = provenance(src, OPTS)
    assert prov.source == "tree.xyz" and prov.source_sha256 == hashlib.sha256(b"1 2 3\n").hexdigest()
    assert prov.parameters["n_main"] == N_M and prov.parameters["alpha"] == 13.0
    ex = make_examples(d.hbl, prov, counter_ids("toy"))
    assert [e.id for e in ex] == [f"toy-{i:03d}" for i in range(N_M)]
    assert sum(len(e.structure.lobes) for e in ex) == N_L
    for e, s in zip(ex, split_structures(d.hbl)):
        assert e.structure.branches[0].parent == -1 and e.descriptors.lobe_count == len(s.lobes)
        assert all(b.parent == 0 for b in e.structure.branches[1:])
        assert all(e.structure.branches[lb.branch].level == Level.SECONDARY for lb in e.structure.lobes)


def _check(d, n_lobes):
    assert len(d.hbl.lobes) == n_lobes and connected(d.hbl)
    assert len(d.hbl.by_level(Level.SECONDARY)) == n_lobes
    assert np.array_equal(np.sort(np.unique(d.lobe_of[d.lobe_of >= 0])), np.arange(n_lobes))


def test_refinement_operations(leaf_on):
    d = leaf_on[2]
    r = refine.remove_lobe(d, 3)
    _check(r, N_L - 1)
    assert not any(np.array_equal(lb.centre, d.hbl.lobes[3].centre) for lb in r.hbl.lobes)
    sel = d.lobes[0].members[: len(d.lobes[0].members) // 2]
    i = refine.insert_lobe(d, sel)
    _check(i, N_L + 1)
    assert np.array_equal(np.sort(i.lobes[-1].members), np.sort(sel))
    m = refine.merge_lobes(d, [1, 2])
    _check(m, N_L - 1)
    assert len(m.lobes[-1].members) == len(d.lobes[1].members) + len(d.lobes[2].members)
    pts = d.hbl.lobes[4].points
    s = refine.split_lobe(d, 4, [pts[:2], pts[-2:]])
    _check(s, N_L + 1)
    assert sum(len(lb.members) for lb in s.lobes[-2:]) == len(d.lobes[4].members)
    assert [crossings(x.hbl) for x in (r, i, m, s)] == [0, 0, 0, 0]


@pytest.mark.parametrize("rounds", [1, 2])
def test_rerouted_kept_lobes_keep_their_places(leaf_on, monkeypatch, rounds):
    # Kept lobes 0 and 2 are made to cross the merged lobe once: they are routed again with it (2 rounds)
    # or left (1 round: no round left); either way every lobe keeps its place and its hull (lobe 0's is
    # grown 10% first, so a hull rebuilt from its points would differ), and the merged one is last.
    from dataclasses import replace

    d = leaf_on[2]
    grown = d.lobes[0].centre + 1.1 * (d.lobes[0].hull_vertices - d.lobes[0].centre)
    d = replace(d, lobes=(replace(d.lobes[0], hull_vertices=grown), *d.lobes[1:]))
    calls = []

    def crossing(lobes, n_kept, tol):  # before and after the new lobe gives way, then never
        calls.append(n_kept)
        return {0, 2} if len(calls) <= 2 else set()

    monkeypatch.setattr(refine, "ROUTE_ROUNDS", rounds)
    monkeypatch.setattr(refine, "_crossing_new", crossing)
    m = refine.merge_lobes(d, [5, 6])
    _check(m, N_L - 1)
    assert calls == ([N_L - 2, N_L - 2] if rounds == 2 else [])  # the last round is not checked
    kept = [k for k in range(N_L) if k not in (5, 6)]
    assert all(np.array_equal(m.lobes[i].members, d.lobes[k].members) for i, k in enumerate(kept))
    assert all(np.array_equal(m.lobes[i].hull_vertices, d.lobes[k].hull_vertices) for i, k in enumerate(kept))
    assert len(m.lobes[-1].members) == len(d.lobes[5].members) + len(d.lobes[6].members)


def test_insert_lobe_rebuilds_the_lobe_it_takes_from(leaf_on):
    from arboretum_server.decompose.clear import inside_foreign

    # The outer third (by distance from the tree's axis) of the lobe whose centre lies nearest that axis
    # (lobe 13 until session 30's k-means, lobe 10 since; of the 40 it is the one whose rest's mean a ring
    # buries): the lobe keeps its place with the rest of its points, a new centre, hull and branch; no branch
    # runs through a lobe it does not feed (1 did when the lobe kept its old branch and got a plain hull).
    d = leaf_on[2]
    j = int(np.argmin([np.linalg.norm(lb.centre[:2]) for lb in d.lobes]))
    m = d.lobes[j].members
    r = np.linalg.norm(d.points[m][:, :2], axis=1)
    i = refine.insert_lobe(d, m[r >= np.quantile(r, 0.67)])
    _check(i, N_L + 1)
    rest = np.sort(m[r < np.quantile(r, 0.67)])
    assert np.array_equal(np.sort(i.lobes[j].members), rest)
    # the lobe sits on the trunk's axis, so the new lobe is a ring round it that buries the mean: the
    # centre moves to one of the lobe's own points outside every other lobe (carve.part_overlaps)
    own, centre = d.points[rest], i.lobes[j].centre
    assert inside_foreign(list(i.lobes), j, own.mean(axis=0)[None])[0]
    assert (np.abs(own - centre).sum(axis=1) < 1e-12).any()
    assert not inside_foreign(list(i.lobes), j, centre[None])[0]
    assert np.allclose(i.lobes[j].segment[-1], i.lobes[j].centre)
    others = [k for k in range(N_L) if k != j]
    assert all(np.array_equal(i.lobes[k].members, d.lobes[k].members) for k in others)
    assert crossings(i.hbl) == 0


def test_refinement_rejects_bad_requests(leaf_on):
    d = leaf_on[2]
    with pytest.raises(InputError, match="does not exist"):
        refine.remove_lobe(d, 99)
    with pytest.raises(InputError, match="at least two"):
        refine.merge_lobes(d, [1, 1])
    with pytest.raises(InputError, match="two strokes"):
        refine.split_lobe(d, 0, [np.zeros((2, 3))])
    with pytest.raises(InputError, match="point indices"):
        refine.insert_lobe(d, [len(d.points) + 5])
    stroke = d.hbl.lobes[0].points[:2]
    bad = [  # wrong types and values a script can pass: one InputError each, never a numpy error
        (lambda: refine.remove_lobe(d, 1.5), "not a lobe number"), (lambda: refine.remove_lobe(d, None), "not a lobe"),
        (lambda: refine.remove_lobe(d, True), "not a lobe"), (lambda: refine.merge_lobes(d, 3), "list of lobe"),
        (lambda: refine.merge_lobes(d, [0.0, 1.0]), "not a lobe"),
        (lambda: refine.insert_lobe(d, [1.5, 2.7]), "integers"),  # not truncated to [1, 2]
        (lambda: refine.insert_lobe(d, np.ones(len(d.points), bool)), "integers"),  # not the 1-point lobe {1}
        (lambda: refine.insert_lobe(d, [[1, 2], [3]]), "integers"),
        (lambda: refine.split_lobe(d, 0, [stroke, np.full((2, 3), np.nan)]), "stroke 1"),
        (lambda: refine.split_lobe(d, 0, [stroke, np.zeros((0, 3))]), "stroke 1"),
        (lambda: refine.split_lobe(d, 0, [stroke[:, :2], stroke[:, :2]]), "stroke 0"),
        (lambda: refine.split_lobe(d, 0, [stroke * 1e300, stroke * -1e300]), "stroke 0 reaches"),  # overflowed
        (lambda: refine.split_lobe(d, 0, [stroke, stroke + 0.01], seed=-1), "seed"),
        (lambda: refine.split_lobe(d, 0, [stroke, stroke + 0.01], seed=2.5), "seed"),
    ]
    for call, message in bad:
        with pytest.raises(InputError, match=message):
            call()
    assert len(refine.remove_lobe(d, np.int64(1)).lobes) == N_L - 1  # numpy integers are lobe numbers
    assert len(refine.split_lobe(d, 0, [stroke, stroke + 0.01], seed=np.int64(3)).lobes) == N_L + 1  # and seeds


def test_cli_stores_examples_and_saves_hbl(truth, tmp_path, capsys):
    from arboretum_library.cli import main
    from arboretum_library.codec import load_record
    from arboretum_library.store import Library

    pts, _ = toy_scan(truth, n=8000)
    scan = tmp_path / "toy.xyz"
    np.savetxt(scan, pts, fmt="%.5f")
    lib, out = tmp_path / "lib", tmp_path / "toy_hbl.npz"
    rc = main(["decompose", str(scan), "--main", "4", "--lobes", "10", "--library", str(lib),
               "--save-hbl", str(out), "--up", "z", "--json"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["stored"]) == 4 and data["stats"]["lobes"] == 10
    assert set(data["timing_s"]) >= {"read", "prepare", "graph", "mains", "lobes", "secondary"}
    with Library.open(lib) as library:
        assert sorted(library.ids()) == sorted(data["stored"])
        ex = library.get(data["stored"][0])
        assert ex.provenance.source == "toy.xyz" and ex.provenance.parameters["n_lobes"] == 10
    hbl = load_record(out, HBL)
    assert len(hbl.lobes) == 10 and len(hbl.by_level(Level.MAIN)) == 4
    assert main(["decompose", str(tmp_path / "missing.xyz")]) == 2
    for bad in ("1.5", "nan"):
        assert main(["decompose", str(scan), "--reach-weight", bad, "--library", str(lib)]) == 2
        assert "--reach-weight must lie in 0..1" in capsys.readouterr().err
    refused = {  # each refused before or during the work, with one line naming the input
        ("--points", "10"): "--points 10 leaves too few points", ("--seed", "-1"): "--seed must not be negative",
        ("--height", "inf"): "--height must be a finite number", ("--lobes", "100000"): "lobes: 100000 asked",
        ("--main", "1000"): "main branches: 1000 asked", ("--save-hbl", str(tmp_path)): "is a folder",
        ("--save-hbl", str(tmp_path / "no" / "x.npz")): "does not exist",
        ("--save-hbl", str(scan)): "writes .npz files, not .xyz",  # it used to turn the scan into a zip
        ("--save-hbl", str(tmp_path / "x.ply")): "not .ply",
    }
    for (flag, value), message in refused.items():
        assert main(["decompose", str(scan), flag, value, "--up", "z", "--library", str(lib)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert str(scan) in err[0] or flag != "--lobes"  # found while decomposing: the scan is named
    assert main(["decompose", str(scan), "--library", "/proc/arboretum-lib"]) == 2  # cannot be created
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "/proc/arboretum-lib" in err[0]
    fresh = tmp_path / "fresh-lib"  # refused while decomposing: the library this run made is gone again
    assert main(["decompose", str(scan), "--lobes", "100000", "--up", "z", "--library", str(fresh)]) == 2
    assert "lobes: 100000 asked" in capsys.readouterr().err and not fresh.exists()
    assert main(["decompose", str(scan), "--main", "4", "--lobes", "10", "--up", "z", "--library", str(lib),
                 "--save-hbl", "/proc/arboretum-hbl.npz"]) == 2  # unwritable: nothing stored either
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]  # after the progress line
    assert len(err) == 1 and "--save-hbl /proc/arboretum-hbl.npz: cannot write it" in err[0]
    with Library.open(lib) as library:  # nothing stored by the refused runs
        assert sorted(library.ids()) == sorted(data["stored"])
    import arboretum_library.store_write as store

    real_write, calls = store.write_folder, []

    def interrupted_write(folder, *args, **kw):  # Ctrl-C while the third example is written
        calls.append(folder)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real_write(folder, *args, **kw)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(store, "write_folder", interrupted_write)
        assert main(["decompose", str(scan), "--main", "4", "--lobes", "10", "--up", "z", "--library", str(lib),
                     "--rebuild"]) == 130  # the same scan and options again: only --rebuild stores it again
    with Library.open(lib) as library:  # the two examples written before it are taken back
        assert len(calls) == 3 and sorted(library.ids()) == sorted(data["stored"])
    assert main(["decompose", str(scan), "--species", "oak", "--up", "z", "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert len(notes) == 1 and "'oak' is not in VRTree Table 2" in notes[0] and "N_m = 8, N_l = 40" in notes[0]
    assert main(["decompose", str(scan), "--species", "oak", "--main", "3", "--up", "z", "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert len(notes) == 1 and "N_l = 40 (the table's medians)" in notes[0] and "N_m" not in notes[0]
    assert main(["decompose", str(scan), "--main", "90", "--up", "z", "--json"]) == 0  # more than the tree has
    data = json.loads(capsys.readouterr().out)
    got = data["stats"]["main_branches"]
    assert got < 90 and data["notes"][0] == (f"{got} main branches found, 90 asked: the other candidate paths "
                                             "merged into them (Algorithm 1)")
    bare = re.fullmatch(rf"(\d+) of {got} examples have no lobes: they grow no twigs or leaves", data["notes"][1])
    assert len(data["notes"]) == 2 and bare and 0 < int(bare[1]) < got  # 8 of 35 until session 30's k-means, 10 since


def test_a_cloud_of_foliage_only_gets_a_note(tmp_path, capsys):
    # a tall Gaussian blob has a trunk base (its narrow lower tail) and decomposes, but 99.8 % of its
    # points read as foliage: the branches have no wood to follow, and the user is told so
    from arboretum_library.cli import main

    blob = tmp_path / "blob.xyz"
    np.savetxt(blob, np.random.default_rng(0).normal(size=(20000, 3)) * [1.0, 1.0, 3.0])
    assert main(["decompose", str(blob), "--up", "z", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["stats"]["labels"] == "guessed" and data["stats"]["leaf_points"] >= 0.95 * data["stats"]["points"]
    assert [n for n in data["notes"] if "are foliage (guessed labels) and almost none wood" in n]
    assert main(["decompose", str(blob), "--up", "z"]) == 0  # the text output carries it too
    share = data["stats"]["leaf_points"] / data["stats"]["points"]
    assert f"note: {share:.1%} of the points are foliage" in capsys.readouterr().out and share < 0.9995


def test_a_straight_line_gets_a_note(tmp_path, capsys):
    # a pole 5 m tall and 1 cm thick with three short stubs has a trunk base and decomposes (its branches
    # lie along it), which it did without a word
    from arboretum_library.cli import main

    pole = tmp_path / "pole.xyz"
    np.savetxt(pole, stubbed_pole(6000))  # a pole alone is refused (session 28): this one has three stubs
    assert main(["decompose", str(pole), "--up", "z", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["stats"]["width_ratio"] < 0.03
    assert [n for n in data["notes"] if n.startswith("the cloud is nearly a straight line")]


def test_a_tree_kept_in_scan_units_of_no_tree_size_gets_a_note(truth, tmp_path, capsys):
    # a scan in millimetres decomposed with --height 0 (keep the scan's units) made a 3,704 m tree
    # without a word; at the default --height (0.8 m) units do not matter and there is no note
    from arboretum_library.cli import main

    pts = toy_scan(truth, 6000)[0]
    scan = tmp_path / "mm.xyz"
    np.savetxt(scan, pts * 1000.0)
    args = ["decompose", str(scan), "--up", "z", "--main", "4", "--lobes", "10", "--json"]
    assert main([*args, "--height", "0"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert abs(data["stats"]["height"] - 1000.0 * np.ptp(pts[:, 2])) < 0.02 * 1000.0 * np.ptp(pts[:, 2])
    (note,) = [n for n in data["notes"] if "scan units tall, kept as metres" in n]
    assert "taller than any tree" in note and "--height METRES" in note
    assert main(args) == 0
    assert not [n for n in json.loads(capsys.readouterr().out)["notes"] if "scan units tall" in n]


def test_virtual_scanner_leaf_off_tree_meets_the_floor():
    from arboretum_server.decompose.report import synth_figures

    f = synth_figures("eucalyptus", 1, "leaf-off", scanner=True)
    assert f["counts_ok"] and f["connected"] and f["crossings"] == 0
    assert f["main_fit"] <= 0.02 and f["leaf_cover"] == 1.0


def test_height_none_keeps_scan_units_and_position(truth):
    pts, _ = toy_scan(truth, n=8000, seed=7)
    shifted = pts + [100.0, -50.0, 20.0]
    d = decompose(shifted, DecomposeOptions(n_main=4, n_lobes=8, height=None))
    assert np.allclose(d.hbl.root, d.root_scan) and abs(d.hbl.root[2] - shifted[:, 2].min()) < 0.05
    assert d.hbl.height == pytest.approx(np.ptp(pts[:, 2]), rel=0.05)
    assert np.allclose(d.hbl.points, shifted[d.source_index])
    lobe = d.hbl.lobes[0].points
    s = refine.split_lobe(d, 0, [lobe[:1], lobe[-1:]])
    assert len(s.hbl.lobes) == 9 and connected(s.hbl)


def test_refinements_reuse_zone_sources_only_while_the_lobes_cover_the_same_points(leaf_on):
    from arboretum_server.decompose.secondary import zone_sources

    def same_as_fresh(x):  # the nearest lobe point within the zone radius, found again from scratch
        fresh = zone_sources(x.points, np.flatnonzero(x.lobe_of >= 0))
        near = lambda s: np.where(s >= 0, np.linalg.norm(x.points - x.points[np.maximum(s, 0)], axis=1), -1.0)  # noqa: E731
        return np.array_equal(fresh >= 0, x.zone_sources >= 0) and np.allclose(near(fresh), near(x.zone_sources))

    d = leaf_on[2]
    assert d.zone_sources is not None and same_as_fresh(d)
    m = refine.merge_lobes(d, [1, 2])
    assert m.zone_sources is d.zone_sources and same_as_fresh(m)  # points traded, union kept: reused
    wood = np.flatnonzero(d.lobe_of < 0)[:40]  # points of no lobe join the new one: found again
    i = refine.insert_lobe(d, np.r_[d.lobes[3].members[:20], wood])
    assert i.zone_sources is not d.zone_sources and same_as_fresh(i)
    assert not np.array_equal(i.zone_sources, d.zone_sources)
