"""Session 17: the last resort (``tunnel.behind``) takes, among the straight routes clear of the kept lobes,
the one through the fewest other new lobes, so it carves fewer of them; before, it took the nearest main
vertex's route and carved whatever lay in its way (forced crossings on the toy tree: 7 of 56 carved a lobe,
now none)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from arboretum_server.decompose import tunnel
from arboretum_server.decompose.clear import boxes, foreign, straight_fallback, straight_routes
from arboretum_server.decompose.merge import resample_step, sample_polylines
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from factories import toy_cloud


@pytest.fixture(scope="module")
def toy():
    return decompose(toy_cloud()[0], DecomposeOptions(points=0, n_main=3, n_lobes=8))


def _crossed(d, j: int, k: int) -> list:
    """The lobes with lobe ``j``'s branch bent through lobe ``k``'s centre."""
    lobes = list(d.lobes)
    seg = lobes[j].segment
    lobes[j] = replace(lobes[j], segment=resample_step(np.array([seg[0], lobes[k].centre, seg[-1]]), 0.005))
    return lobes


def test_forced_crossings_are_cleared_without_carving(toy):
    tol = toy.options.step / 2
    cleared = carved = 0
    for j in range(len(toy.lobes)):
        for k in range(len(toy.lobes)):
            lobes = _crossed(toy, j, k) if k != j else None
            if lobes is None or not foreign(lobes, j, lobes[j].segment, tol, boxes(lobes)):
                continue
            before = list(lobes)
            assert tunnel.behind(lobes, 0, toy.points, toy.mains, toy.options) == 1
            assert not any(foreign(lobes, i, lb.segment, tol, boxes(lobes)) for i, lb in enumerate(lobes))
            carved += sum(a.hull_vertices is not b.hull_vertices for a, b in zip(before, lobes))
            cleared += 1
    assert cleared == 56 and carved == 0


def _in_way(lobes, j: int, route, step: float) -> int:
    """How many lobes other than ``j`` the route's segment enters."""
    wood = sample_polylines([route[0]], step)
    return sum(tunnel.enters(lobes[i], wood) for i in range(len(lobes)) if i != j)


def test_routes_come_fewest_lobes_in_the_way_first(toy):
    step = 0.0025
    for j, k in ((0, 3), (2, 5), (6, 1)):
        lobes = _crossed(toy, j, k)
        routes = list(tunnel._routes(lobes, 0, j, toy.points, toy.mains, step))
        every = straight_routes([lobes[j]], 0, toy.mains)
        assert 1 <= len(routes) <= tunnel.ROUTES_TRIED and len(every) > len(routes)

        counts = [_in_way(lobes, j, r, step) for r in routes]
        assert counts == sorted(counts) and counts[0] == min(_in_way(lobes, j, r, step) for r in every)


def test_straight_routes_are_the_clear_ones_nearest_first(toy):
    lobes = list(toy.lobes)
    for j in range(len(lobes)):
        routes = straight_routes(lobes, j, toy.mains)
        first = straight_fallback(lobes, j, toy.mains)
        assert (first is None) == (not routes)
        if first is not None:
            assert np.array_equal(routes[0][0], first[0]) and routes[0][1:] == first[1:]
        starts = [np.linalg.norm(r[0][0] - lobes[j].centre) for r in routes]
        assert starts == sorted(starts)
        tol = toy.options.step / 2
        assert not any(foreign(lobes, j, r[0], tol) for r in routes)
