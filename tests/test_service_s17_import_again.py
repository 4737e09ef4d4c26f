"""Session 17 (helper-126's hunt): the service's ``library.import`` sent twice with the same points, name
and options stores its examples once (before: twice, so a client retrying after a timeout doubled them),
as ``arboretum decompose`` and ``refine.commit`` already did."""

from __future__ import annotations

import numpy as np

from arboretum_library.store import Library
from arboretum_server.service.handlers.library import import_job, points_sha256

OPTIONS = {"n_main": 3, "n_lobes": 8, "points": 2000}


def _import(lib, pts, labels=None, name="toy", options=OPTIONS):
    return import_job(lambda *a, **k: None, str(lib), pts, labels, name, "unknown", options)


def test_the_same_import_again_stores_nothing_and_names_what_is_there(tmp_path):
    from factories import toy_cloud

    pts = toy_cloud()[0]
    lib = tmp_path / "lib"
    Library.open(lib, create=True).close()
    first = _import(lib, pts)
    assert len(first["ids"]) == 3
    again = _import(lib, pts.copy())
    assert again["ids"] == [] and again["notes"] == [
        f"already in the library as ids {', '.join(sorted(first['ids']))} (these points, imported with the same "
        "options): nothing stored"]
    other = _import(lib, pts, options={**OPTIONS, "seed": 1})  # other options: a new run
    renamed = _import(lib, pts, name="toy-2")  # a new name: the user's new import
    moved = _import(lib, pts + [0.0, 0.0, 0.001])  # other points
    assert [len(r["ids"]) for r in (other, renamed, moved)] == [3, 3, 3]
    with Library.open(lib) as opened:
        assert len(opened.ids()) == 12


def test_points_digest_reads_values_not_layout():
    pts = np.arange(30, dtype=np.float64).reshape(10, 3)
    assert points_sha256(pts, None) == points_sha256(np.asfortranarray(pts), None)
    assert points_sha256(pts, None) == points_sha256(pts.astype(">f8"), None)
    assert points_sha256(pts, None) != points_sha256(pts, np.zeros(10, np.uint8))
    assert points_sha256(pts, None) != points_sha256(pts[::-1], None)
