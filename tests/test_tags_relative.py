"""'straight' and 'curved' relative to the library: the straighter and curvier thirds of each species."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_library.descriptors import (
    RELATIVE_MIN,
    relative_curvature_tags,
    tags_for,
    tercile_bounds,
)
from arboretum_library.store import Library
from factories import make_example


def _with_curvature(ex, curvature: float):
    d = dataclasses.replace(ex.descriptors, curvature=curvature)
    return dataclasses.replace(ex, descriptors=d, tags=tags_for(d))


@pytest.fixture
def lib(tmp_path, rng):
    """12 oaks bowing 0.9-2.0 rad (all 'curved' by the fixed thresholds) and 3 pines (too few to be relative)."""
    with Library.open(tmp_path / "lib", create=True, fsync=False) as library:
        for i, c in enumerate(np.linspace(0.9, 2.0, 12)):
            library.add(_with_curvature(make_example(rng, id=f"oak-{i:02d}", species="oak"), float(c)))
        for i, c in enumerate((0.2, 0.5, 0.9)):
            library.add(_with_curvature(make_example(rng, id=f"pine-{i}", species="pine"), c))
        yield library


def test_keywords_split_a_species_into_thirds(lib):
    assert [e.id for e in lib.entries(tags="straight", species="oak")] == [f"oak-{i:02d}" for i in range(4)]
    assert [e.id for e in lib.entries(tags=["curved"], species="oak")] == [f"oak-{i:02d}" for i in range(8, 12)]
    hits = lib.search("straight oak", limit=4)
    assert [h.id for h in hits] == [f"oak-{i:02d}" for i in range(4)] and all(h.score == 1.0 for h in hits)
    assert lib.entry("oak-00").tags == lib.entries(species="oak")[0].tags and "straight" in lib.entry("oak-00").tags
    # the catalog keeps the fixed thresholds: every oak was 'curved' when it was added
    stored = dict(lib._con.execute("SELECT id, tags FROM examples WHERE species = 'oak'").fetchall())
    assert all("curved" in t.split() for t in stored.values())


def test_small_species_keep_the_fixed_thresholds_and_info_counts_what_search_sees(lib):
    pines = {e.id: e.tags for e in lib.entries(species="pine")}
    assert "straight" in pines["pine-0"] and "curved" in pines["pine-2"]
    assert not {"straight", "curved"} & set(pines["pine-1"])
    info = lib.info()
    assert info["tags"]["straight"] == 4 + 1 and info["tags"]["curved"] == 4 + 1


def test_other_filters_do_not_change_the_thirds(lib):
    dense = {e.id for e in lib.entries(tags=["curved"], species="oak", min_curvature=1.5)}
    assert dense == {f"oak-{i:02d}" for i in range(8, 12)}


def test_relative_tags_rules():
    assert tercile_bounds(np.arange(RELATIVE_MIN - 1)) is None
    lo, hi = tercile_bounds(np.arange(9.0))
    assert (lo, hi) == pytest.approx((8 / 3, 16 / 3))
    assert relative_curvature_tags(("dense", "curved"), 0.5, (1.0, 2.0)) == ("dense", "straight")
    assert relative_curvature_tags(("curved", "sparse"), 1.5, (1.0, 2.0)) == ("sparse",)
    assert relative_curvature_tags(("sparse",), 3.0, (1.0, 2.0)) == ("sparse", "curved")
    assert relative_curvature_tags((), 0.35, None) == () and relative_curvature_tags((), 0.3, None) == ("straight",)
