"""``arboretum photos``: the same photographs and seed give the same matches, run after run.

24 views at 512x384, 2,048 SIFT features each: all register, about 1,800 points, 17 s a reconstruction.

Before session 18 they did not: extraction threads numbered the images in the order they finished, and
geometric verification drew a fresh RANSAC seed each run (COLMAP's ``random_seed = -1``), so 41-43 of
the 276 verified pairs of the slow test's 24 views differed between two runs and so did the cloud.
The mapping on equal matches is not proven repeatable (docs/photos.md).
"""

from __future__ import annotations

import sqlite3

import pytest

VIEWS = 24


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    pytest.importorskip("pycolmap")
    from tests.photo_fixtures import render_photos

    from arboretum_server.synth.harmonic import grow_species

    return render_photos(grow_species("apple", 1), tmp_path_factory.mktemp("images"), views=VIEWS, size=(512, 384))


def _run(photos, work):
    from arboretum_server.photos.reconstruct import ReconstructOptions, reconstruct

    return reconstruct(photos.folder, ReconstructOptions(max_features=2048, max_image_size=512), work=work)


def _verified(db) -> dict[int, tuple[int, bytes]]:
    with sqlite3.connect(db) as c:
        return {pair: (rows, bytes(data or b"")) for pair, rows, data in
                c.execute("select pair_id, rows, data from two_view_geometries")}


@pytest.mark.slow
def test_reconstruct_twice_gives_the_same_cloud(photos, tmp_path):
    a, b = _run(photos, tmp_path / "a"), _run(photos, tmp_path / "b")
    with sqlite3.connect(tmp_path / "a" / "database.db") as c:
        names = [n for _, n in c.execute("select image_id, name from images order by image_id")]
    assert names == photos.names  # ids in name order, not in the order extraction threads finished
    assert _verified(tmp_path / "a" / "database.db") == _verified(tmp_path / "b" / "database.db")
    assert a.stats["registered"] >= VIEWS - 2 and len(a.points) >= 100
    assert a.image_names == b.image_names and len(a.points) == len(b.points)
    # the mapping on equal matches gave the same points in another frame in one whole slow-suite run
    # (session 18; not again alone): its threads are not proven repeatable, so the coordinates are not
    # compared
