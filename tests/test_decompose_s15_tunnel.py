"""A decomposition's secondary branch that no repair of ``make_lobes`` clears (session 15): its way is
carved through the lobes in it, or its lobe's centre moves (``tunnel.behind`` with every lobe new), so
no branch runs through a lobe it does not feed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from arboretum_server.decompose.clear import boxes, foreign
from arboretum_server.decompose.evaluate import crossings
from arboretum_server.decompose.merge import resample_step
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from arboretum_server.decompose.tunnel import behind
from factories import toy_cloud

OPTS = DecomposeOptions(points=0, n_main=3, n_lobes=8)


@pytest.fixture(scope="module")
def toy():
    return decompose(toy_cloud()[0], OPTS)


def _through(lobes, j: int, k: int) -> np.ndarray:
    """Lobe ``j``'s branch bent through the middle of lobe ``k`` (start and end kept)."""
    seg = lobes[j].segment
    return resample_step(np.array([seg[0], lobes[k].centre, seg[-1]]), 0.005)


def _crossing_pair(lobes, tol):
    """(j, k): a lobe j whose branch, bent through lobe k's centre, enters a lobe it does not feed."""
    for j in range(len(lobes)):
        for k in range(len(lobes)):
            if k != j:
                trial = list(lobes)
                trial[j] = replace(lobes[j], segment=_through(lobes, j, k))
                if foreign(trial, j, trial[j].segment, tol, boxes(trial)):
                    return j, k
    raise AssertionError("no lobe to cross")


def test_a_crossing_branch_gets_a_clear_way_and_the_rest_stay_clear(toy):
    tol = toy.options.step / 2
    lobes = list(toy.lobes)
    assert not any(foreign(lobes, j, lb.segment, tol, boxes(lobes)) for j, lb in enumerate(lobes))
    j, k = _crossing_pair(lobes, tol)
    lobes[j] = replace(lobes[j], segment=_through(lobes, j, k))
    assert behind(lobes, 0, toy.points, toy.mains, toy.options) == 1
    assert not any(foreign(lobes, i, lb.segment, tol, boxes(lobes)) for i, lb in enumerate(lobes))
    assert np.allclose(lobes[j].segment[-1], lobes[j].centre) and lobes[j].parent >= 0
    assert [len(lb.members) for lb in lobes] == [len(lb.members) for lb in toy.lobes]  # hulls and ways change
    assert behind(lobes, 0, toy.points, toy.mains, toy.options) == 0  # nothing left to clear


def test_decompose_clears_what_the_repairs_left_crossing(monkeypatch):
    """A branch bent through another lobe after every repair of ``make_lobes`` (its last step, ``behind``,
    is where the crossing goes in) comes out clear, counted in ``stats.tunnelled``."""
    from arboretum_server.decompose import secondary

    cleared = secondary.behind

    def crossing(lobes, n_kept, *args, **kwargs):
        j, k = _crossing_pair(lobes, OPTS.step / 2)
        lobes[j] = replace(lobes[j], segment=_through(lobes, j, k))
        return cleared(lobes, n_kept, *args, **kwargs)

    monkeypatch.setattr(secondary, "behind", crossing)
    d = decompose(toy_cloud()[0], OPTS)
    assert d.stats["tunnelled"] == 1 and crossings(d.hbl) == 0
    assert len(d.hbl.lobes) == 8


def test_the_scanned_pine_that_crossed_is_clear(monkeypatch):
    """The virtual scanner's pine, seed 13, leaf-on: one lobe at the top of the leader had a branch up the
    crown through 8 lobes (0.56 of the height); it now starts at the trunk's top vertex, one lobe carved
    round it, the leaves still covered."""
    from arboretum_library.model import LEAF
    from arboretum_server.decompose import tunnel
    from arboretum_server.decompose.evaluate import COVER_TOL, lobe_distance
    from arboretum_server.decompose.report import grow_truth, virtual_scan

    carved = []
    real = tunnel.carve_lobe

    def counted(lobes, k, *a, **kw):
        carved.append(k)
        return real(lobes, k, *a, **kw)

    monkeypatch.setattr(tunnel, "carve_lobe", counted)
    pts, lab = virtual_scan(grow_truth("harmonic", "pine", 13), "leaf-on", 13)
    d = decompose(pts, DecomposeOptions(species="pine"))
    assert d.stats["tunnelled"] == 1 and crossings(d.hbl) == 0 and len(carved) == 1
    lengths = [float(np.linalg.norm(np.diff(lb.segment, axis=0), axis=1).sum()) for lb in d.lobes]
    assert max(lengths) < 0.3 and len(d.lobes) == 40
    leaves = d.to_output((pts[lab == LEAF] - d.root_scan) * d.scale)
    assert (lobe_distance(d.hbl, leaves) <= COVER_TOL * d.hbl.height / 0.8).mean() >= 0.998


def test_when_no_carving_clears_it_the_lobe_centre_moves(toy, monkeypatch):
    from arboretum_server.decompose import tunnel

    monkeypatch.setattr(tunnel, "carve_route", lambda *a, **k: False)
    tol = toy.options.step / 2
    lobes = list(toy.lobes)
    j, k = _crossing_pair(lobes, tol)
    lobes[j] = replace(lobes[j], segment=_through(lobes, j, k))
    assert behind(lobes, 0, toy.points, toy.mains, toy.options) == 1
    assert not foreign(lobes, j, lobes[j].segment, tol, boxes(lobes)) and len(lobes) == 8
    assert not np.array_equal(lobes[j].centre, toy.lobes[j].centre)
    assert any(np.abs(toy.points[lobes[j].members] - lobes[j].centre).sum(axis=1) == 0)  # one of its points
    assert all(lobes[i] is toy.lobes[i] for i in range(8) if i != j)  # nothing else touched
