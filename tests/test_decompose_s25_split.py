"""Session 25 split ``ground`` and ``trunkbase`` in three modules each (behaviour unchanged): the public
names stay importable from where callers import them, as the one definition each (no second copy), and
the private names the tests reach live in one module each."""

import numpy as np

from arboretum_server.decompose import (
    ground,
    ground_cut,
    ground_surface,
    trunkbase,
    trunkbase_links,
    trunkbase_piece,
)


def test_public_names_stay_where_callers_import_them():
    assert ground.Ground is ground_surface.Ground and ground.body_span is ground_surface.body_span
    assert trunkbase.detached is trunkbase_piece.detached and trunkbase.under is trunkbase_piece.under
    assert trunkbase.plan_radius is trunkbase_links.plan_radius
    assert sorted(ground.__all__) == ["Found", "Ground", "body_span", "find_ground"]
    assert sorted(trunkbase.__all__) == ["detached", "find_root", "plan_radius", "under"]


def test_each_name_is_defined_in_one_module():
    modules = (ground, ground_cut, ground_surface, trunkbase, trunkbase_links, trunkbase_piece)
    for name in ("_cut", "_surface", "_candidates", "_link", "_dense_start", "_filled", "ground_plane"):
        homes = {getattr(m, name).__module__ for m in modules if hasattr(m, name)}
        assert len(homes) == 1, (name, homes)
    assert ground_surface._candidates.__module__.endswith(".ground_surface")
    assert trunkbase_links._link.__module__.endswith(".trunkbase_links")


def test_the_ground_found_through_the_split_modules_is_the_plane_it_was():
    # a flat disc 10 wide of 4,000 points under a column 5 tall: the plane z = 0, every disc point cut
    rng = np.random.default_rng(0)
    r, a = 5 * np.sqrt(rng.uniform(0, 1, 4000)), rng.uniform(0, 2 * np.pi, 4000)
    disc = np.c_[r * np.cos(a), r * np.sin(a), np.zeros(4000)]
    z = rng.uniform(0, 5, 3000)
    t = rng.uniform(0, 2 * np.pi, 3000)
    trunk = np.c_[0.1 * np.cos(t), 0.1 * np.sin(t), z]
    cut, surface = ground.find_ground(np.r_[disc, trunk], 0.015)
    assert isinstance(surface, ground_surface.Ground) and surface.bend is None
    assert np.allclose(surface.plane, 0.0, atol=1e-4)  # 2e-5 off: trunk points within the band refit it
    assert cut[:4000].all() and cut[4000:].sum() < 0.05 * 3000
