"""A pole, a bare stem or a straight line is refused, not decomposed into lobes sliced along it (session 28).

A vertical line of 600 points decomposed into one main branch and 40 lobes, while a plane, a slanted line
and points at one height were refused. ``preprocess.check_pole`` refuses a cloud of which 99 % of the
points lie within 2.5 % of its length of one straight line, on every path (the library, the command,
``library build``, the service's import); the narrowest real tree measured (scan 10's pine, clipped
1.25 m round its stem) keeps 36 % of its points beyond that.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.pointio import ReadOptions, read_points
from arboretum_server.decompose.options import DecomposeOptions
from arboretum_server.decompose.pipeline import decompose
from conftest import SHARED_SCANS

LINE = np.c_[np.zeros(600), np.zeros(600), np.linspace(0, 5, 600)]
"""The hostile-input probe's vertical line (session 27): 600 points, 5 long."""


def cylinder(radius: float, noise: float, n: int = 6000, height: float = 10.0, seed: int = 0) -> np.ndarray:
    """(n, 3) points on a vertical cylinder's surface, with Gaussian noise of ``noise`` (scan units)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 2 * np.pi, n)
    pts = np.c_[radius * np.cos(t), radius * np.sin(t), rng.uniform(0, height, n)]
    return pts + rng.normal(0, noise, pts.shape)


def test_the_vertical_line_is_refused_saying_what_it_is():
    with pytest.raises(InputError) as e:
        decompose(LINE, DecomposeOptions())
    assert str(e.value) == ("point cloud: all 600 points lie on one straight line 5 long: a pole or a stem without "
                            "branches, not a tree to decompose")


@pytest.mark.parametrize("radius", [0.05, 0.1, 0.2])  # 0.5, 1 and 2 % of the height, noise 0.2 % of it
def test_thin_poles_are_refused(radius):
    with pytest.raises(InputError, match=r"of the 6,000 points lie within [0-9.]+ of one straight line \("):
        decompose(cylinder(radius, 0.02), DecomposeOptions())


def test_a_noisy_line_and_a_leaning_pole_are_refused():
    rng = np.random.default_rng(1)
    noisy = np.c_[rng.normal(0, 0.05, (6000, 2)), rng.uniform(0, 10, 6000)]  # noise 0.5 % of the height
    c, s = np.cos(0.35), np.sin(0.35)  # 20 degrees off the vertical
    leaning = cylinder(0.1, 0.01) @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]])
    for pts in (noisy, leaning):
        with pytest.raises(InputError, match="a pole or a stem without branches"):
            decompose(pts, DecomposeOptions())


def test_the_boundary_lies_between_a_2_and_a_3_percent_stem():
    from arboretum_server.decompose.preprocess import POLE, PoleError, axis_distances, check_pole

    for radius in (0.3, 0.5):  # 3 and 5 % of the height: a stout stem or a stump, decomposed as before
        check_pole(cylinder(radius, 0.02))
    with pytest.raises(PoleError):
        check_pole(cylinder(0.2, 0.02))
    across, length = axis_distances(cylinder(0.3, 0.0))
    assert length == pytest.approx(10.0, abs=0.01) and np.median(across) == pytest.approx(0.3, rel=1e-4)
    assert POLE == 0.025


def test_a_line_with_stubs_holding_over_1_percent_of_the_points_is_let_through():
    from arboretum_server.decompose.preprocess import check_pole

    rng = np.random.default_rng(0)
    pole = np.c_[rng.normal(0, 0.01, (6000, 2)), rng.uniform(0, 5, 6000)]
    d = rng.uniform(0, 0.25, (3, 200))  # three 0.25 m stubs, 3 % of the points each
    stubs = [np.c_[r * np.cos(a), r * np.sin(a), z + 0.5 * r] for r, a, z in zip(d, (0, 2.1, 4.2), (2, 3, 4))]
    check_pole(np.vstack([pole, *stubs]))
    with pytest.raises(InputError, match="5,940 of the 6,000 points"):
        check_pole(pole)


@pytest.mark.skipif(not SHARED_SCANS.is_dir(), reason="the shared real scans are not here")
@pytest.mark.parametrize("scan", ["01_rtwig_coffeetree", "06_adtree_tree7", "07_itsme_buttressed_tree_1",
                                  "10_treels_pine"])
def test_no_real_scan_is_refused(scan):
    from arboretum_server.decompose.preprocess import POLE, axis_distances, prepare

    cloud = read_points(SHARED_SCANS / scan / f"{scan}.xyz", ReadOptions())
    prep = prepare(cloud.points, DecomposeOptions(), np.random.default_rng(0))  # check_pole runs in it
    across, length = axis_distances(prep.points)
    assert np.mean(across > POLE * length) > 0.3  # 36 % (the pine) to 98 % of the points beyond the bound


def test_the_refusal_carries_no_precision_or_way_up_note():
    from arboretum_server.decompose.notes import refusal
    from arboretum_server.decompose.preprocess import PoleError

    said = refusal("scan.xyz: point cloud: ...", "a 0.5 m grid", PoleError("..."), "is the file upside down?")
    assert said == "scan.xyz: point cloud: ..."


def test_the_command_refuses_it_in_one_line_and_leaves_no_library(tmp_path, capsys):
    from arboretum_library.cli import main

    scan, lib = tmp_path / "pole.xyz", tmp_path / "lib"
    np.savetxt(scan, LINE)
    assert main(["decompose", str(scan), "--library", str(lib)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"arboretum decompose: error: {scan}: point cloud: all 600 points lie on one straight line 5 long: "
                   "a pole or a stem without branches, not a tree to decompose"]
    assert not lib.exists()


def test_library_build_reports_it_failed(tmp_path, capsys):
    pytest.importorskip("distributed")
    from arboretum_library.cli import main

    scan, lib = tmp_path / "pole.xyz", tmp_path / "lib"
    np.savetxt(scan, cylinder(0.1, 0.02))
    assert main(["library", "build", str(scan), "--library", str(lib), "--workers", "1", "--json"]) == 1
    capsys.readouterr()
    report = json.loads(Path(f"{lib}-report/report.json").read_text())
    assert (report["scans"], report["added"], report["failed"]) == (1, 0, 1)
    assert report["records"][0]["error"].endswith("of one straight line (1.5% of its length 10.1): a pole or a stem "
                                                  "without branches, not a tree to decompose")


def test_the_service_import_refuses_it_as_bad_input(tmp_path):
    from arboretum_library.protocol_base import error_code
    from arboretum_library.store import Library
    from arboretum_server.service.handlers.library import import_job

    Library.open(tmp_path / "lib", create=True).close()
    with pytest.raises(InputError, match="a pole or a stem without branches") as e:
        import_job(lambda *a: None, str(tmp_path / "lib"), cylinder(0.1, 0.02, n=3000), None, "pole", "unknown",
                   {"points": 2000})
    assert error_code(e.value) == "bad_input"
    with Library.open(tmp_path / "lib") as lib:
        assert len(lib.ids()) == 0
