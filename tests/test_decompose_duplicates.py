"""Repeated points in a scan: exact duplicates merged before anything else (``repeats.distinct_rows``),
a far pile of them (a scanner's no-return rows at (0, 0, 0)) left out, and the note that says so."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.model import LEAF, WOOD
from arboretum_library.repeats import _groups, _row_hash, distinct_rows
from arboretum_server.decompose.notes import notes, repeated_note, scan_notes
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from arboretum_server.decompose.preprocess import prepare
from arboretum_server.decompose.toytree import toy_scan, toy_truth

OPTS = DecomposeOptions(n_main=6, n_lobes=20, points=4000)
SHIFT = np.array([40.0, 30.0, 16.0])
"""The toy tree (8 m tall) moved so that (0, 0, 0) lies 50 m off in plan and 16 m below its base."""


def _hbl_hash(d) -> str:
    h = hashlib.sha1()
    for b in d.hbl.branches:
        h.update(b.points.tobytes())
    for lb in d.hbl.lobes:
        h.update(lb.hull_vertices.tobytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def tree():
    return toy_scan(toy_truth(), n=8000, seed=3)


@pytest.fixture(scope="module")
def base(tree):
    return decompose(tree[0], OPTS)


def _first_rows(cloud: np.ndarray) -> set[int]:
    """The first row of ``cloud`` holding each distinct point (the obviously-correct reference)."""
    return set(np.unique(cloud, axis=0, return_index=True)[1].tolist())


def _same_tree(d, base) -> None:
    assert len(np.unique(d.points, axis=0)) == len(d.points) == len(base.points)
    assert (d.stats["main_branches"], d.stats["lobes"], d.stats["hull_fallbacks"]) == (
        base.stats["main_branches"], base.stats["lobes"], base.stats["hull_fallbacks"])
    assert np.array_equal(d.root_scan, base.root_scan)
    assert _hbl_hash(d) == _hbl_hash(base)


def test_copies_of_one_point_are_one_point(tree, base):
    pts = tree[0]
    cloud = np.r_[pts, np.repeat(pts[500:501], 50_000, axis=0)]
    d = decompose(cloud, OPTS)
    _same_tree(d, base)
    assert base.stats["lobes"] == 20 and base.stats["hull_fallbacks"] == 0
    assert set(d.source_index.tolist()) <= _first_rows(cloud)
    assert np.array_equal(cloud[d.source_index], pts[base.source_index])
    note = ("50,000 repeated points merged, each point is used once: 50,001 rows hold the point "
            f"({', '.join(f'{v:.7g}' for v in pts[500])}), scan units")
    assert scan_notes({"repeated": prepare(cloud, OPTS, np.random.default_rng(0)).repeats.as_stats()}) == [note]


def test_the_note_comes_with_the_decomposition(tree, base):
    pts = tree[0]
    d = decompose(np.r_[pts, pts[:2000]], OPTS)  # needs stats["repeated"] (pipeline.py, one line)
    assert d.stats["repeated"]["merged"] == 2000 and d.stats["repeated"]["rows"] == 10_000
    assert notes(OPTS, d.stats) == ["2,000 repeated points merged, each point is used once: 2,000 points are "
                                    "given 2 times each"]
    assert notes(OPTS, base.stats) == [] and base.stats["repeated"]["merged"] == 0


def test_every_point_twice_gives_the_tree_of_once(tree, base):
    pts = tree[0]
    cloud = np.r_[pts, pts[np.random.default_rng(1).permutation(len(pts))]]
    d = decompose(cloud, OPTS)
    _same_tree(d, base)
    assert set(d.source_index.tolist()) <= _first_rows(cloud)
    rep = prepare(cloud, OPTS, np.random.default_rng(0)).repeats
    assert rep[:5] == (16000, 8000, 8000, 2, 2) and not rep.left_out
    assert repeated_note(rep.as_stats()) == ("8,000 repeated points merged, each point is used once: 8,000 points "
                                             "are given 2 times each")


def test_no_return_rows_at_the_origin_are_left_out(tree):
    pts = tree[0] + SHIFT
    alone = decompose(pts, OPTS)
    cloud = np.r_[pts[:3000], np.zeros((50_000, 3)), pts[3000:]]
    d = decompose(cloud, OPTS)
    assert d.stats["main_branches"] == alone.stats["main_branches"] == 6 and d.stats["lobes"] == 20
    assert np.linalg.norm(d.root_scan - alone.root_scan) < 0.01
    assert not (cloud[d.source_index] == 0).all(axis=1).any()
    assert np.array_equal(cloud[d.source_index], pts[alone.source_index])
    rep = prepare(cloud, OPTS, np.random.default_rng(0)).repeats
    assert rep.left_out and rep.at == (0.0, 0.0, 0.0) and rep.most == 50_000
    assert rep.apart == pytest.approx(np.linalg.norm(pts, axis=1).min())
    note = repeated_note(rep.as_stats())
    assert note == ("49,999 repeated points merged, each point is used once: 50,000 rows hold the point (0, 0, 0), "
                    f"scan units (no-return rows of the scanner?); it lies {rep.apart:.3g} from every other point "
                    "and was left out")


def test_all_points_of_a_pile_of_50k_copies(tree):
    pts = tree[0]
    opts = DecomposeOptions(n_main=6, n_lobes=20, points=0)
    d = decompose(np.r_[pts, np.repeat(pts[:1], 50_000, axis=0)], opts)
    assert d.stats["points"] == len(pts) == len(np.unique(d.points, axis=0))
    assert np.array_equal(np.sort(d.source_index), np.arange(len(pts)))
    assert d.stats["main_branches"] == 6 and d.stats["lobes"] == 20


def test_a_repeated_point_keeps_its_first_rows_label(tree):
    pts, lab = tree
    cloud = np.r_[pts, pts]
    given = np.r_[lab, np.where(lab == LEAF, WOOD, LEAF)]  # the copies say the opposite
    p = prepare(cloud, OPTS, np.random.default_rng(0), given)
    assert p.source_index.max() < len(pts)
    assert np.array_equal(p.labels, lab[p.source_index])


def test_too_few_distinct_points_is_refused():
    rng = np.random.default_rng(0)
    few = rng.normal(size=(150, 3))
    with pytest.raises(InputError, match=r"150 distinct points \(1,?350 repeated rows merged\), need at least 200"):
        decompose(np.repeat(few, 10, axis=0), OPTS)


def test_distinct_rows_matches_numpy_unique():
    rng = np.random.default_rng(4)
    pts = np.round(rng.normal(size=(5000, 3)), 1)  # coarse: many repeats, most points distinct
    pts[::7, 2] = -0.0
    pts[1::7, 2] = 0.0  # -0.0 and 0.0 are one coordinate
    first, rep = distinct_rows(pts)
    ref = _first_rows(pts + 0.0)
    assert set(np.flatnonzero(first).tolist()) == ref
    n = np.unique(pts + 0.0, axis=0, return_counts=True)[1]
    assert rep.rows == 5000 and rep.merged == 5000 - len(ref) and rep.repeated == int((n > 1).sum())
    assert (rep.most, rep.fewest) == (int(n.max()), int(n[n > 1].min()))
    assert int((pts == np.asarray(rep.at)).all(axis=1).sum()) == rep.most


def test_hash_collisions_fall_back_to_the_exact_sort():
    rng = np.random.default_rng(5)
    pts = rng.integers(0, 4, (400, 3)).astype(np.float64)
    collide = np.zeros(len(pts), np.uint64)  # every row "hashes" alike
    order, start = _groups(pts, collide, collide)
    runs = np.split(order, np.flatnonzero(start)[1:])
    assert len(runs) == len(np.unique(pts, axis=0))
    assert all((pts[r] == pts[r[0]]).all() and (np.diff(r) > 0).all() for r in runs)
    assert {int(r[0]) for r in runs} == _first_rows(pts)
    assert np.array_equal(_row_hash(np.array([[0.0, -0.0, 1.0]])), _row_hash(np.array([[-0.0, 0.0, 1.0]])))


def test_a_cloud_without_repeats_is_left_as_it_is(tree):
    first, rep = distinct_rows(tree[0])
    assert first.all() and rep.merged == 0 and rep.at is None
    assert repeated_note(rep.as_stats()) is None


def test_few_repeats_give_no_note_but_a_spread_is_described():
    assert repeated_note({"rows": 10_000, "merged": 99, "repeated": 99, "most": 2, "fewest": 2,
                          "at": [1.0, 2.0, 3.0], "apart": 0.01, "left_out": False}) is None
    assert repeated_note({"rows": 10_000, "merged": 300, "repeated": 120, "most": 4, "fewest": 2,
                          "at": [1.0, 2.0, 3.0], "apart": 0.01, "left_out": False}) == (
        "300 repeated points merged, each point is used once: 120 points are given 2 to 4 times")


def test_the_up_axis_guess_is_not_fooled_by_a_pile_of_copies():
    from arboretum_library.pointio import guess_up_axis

    rng = np.random.default_rng(4)
    trunk = np.c_[rng.normal(0, 0.05, (4000, 2)), rng.uniform(0, 3, 4000)]
    crown = rng.normal(0, 1, (16000, 3)) * [1.2, 1.2, 0.8] + [0, 0, 4]
    cloud = np.vstack([trunk, crown]) + [300.0, 200.0, 50.0]  # a tree standing along +Z, away from the origin
    piled = np.vstack([cloud, np.zeros((200_000, 3))])  # no-return rows at (0, 0, 0)
    axis, confidence = guess_up_axis(cloud)
    assert axis == "z" and confidence > 0.9
    again, sure = guess_up_axis(piled)  # the pile is one point among 20,000 (before: 45,000 of the 50,000 sampled)
    assert again == axis and abs(sure - confidence) < 0.01
