"""Review findings on the point-cloud readers (session 10): PDAL CSV colours, the spacing of a scan
with a stray point, ``# comments`` after data, .npy look-alikes with accents, multi-block .pts files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import arboretum_library
from arboretum_library import pointio_spatial
from arboretum_library.errors import InputError
from arboretum_library.pointio import ReadOptions, median_spacing, read_points
from arboretum_library.pointio_text import find_header, sniff_not_points
from test_pointio_s10_spacing import _brute_force  # the exact reference

Z = ReadOptions(up="z")
PDAL_HEADER = ("X,Y,Z,Intensity,ReturnNumber,NumberOfReturns,ScanDirectionFlag,EdgeOfFlightLine,"
               "Classification,ScanAngleRank,UserData,PointSourceId,GpsTime")


def _pdal_rows(rng, n=200):
    xyz = np.c_[rng.normal(0, 1, (n, 2)), rng.uniform(0, 10, n)]
    return [f"{x:.3f},{y:.3f},{z:.3f},{rng.integers(0, 256)},{rng.integers(1, 4)},3,0,0,5,0,0,1,12.5"
            for x, y, z in xyz], xyz


def test_a_header_naming_xyz_without_colours_gets_no_colours_guessed(tmp_path, rng):
    """Before: Intensity, ReturnNumber, NumberOfReturns (all within 0..255) were read as RGB."""
    rows, xyz = _pdal_rows(rng)
    quoted = '"' + PDAL_HEADER.replace(",", '","') + '"'
    (tmp_path / "pdal.csv").write_text(quoted + "\n" + "\n".join(rows) + "\n")
    cloud = read_points(tmp_path / "pdal.csv", Z)
    assert cloud.colors is None
    np.testing.assert_allclose(cloud.points, np.round(xyz, 3))
    # named colours still count, anywhere in the header
    rgb = rng.integers(0, 256, (len(xyz), 3))
    named = ["Intensity,X,Y,Z,Red,Green,Blue"] + [
        f"7,{x:.3f},{y:.3f},{z:.3f},{r},{g},{b}" for (x, y, z), (r, g, b) in zip(xyz, rgb)
    ]
    (tmp_path / "named.csv").write_text("\n".join(named) + "\n")
    np.testing.assert_allclose(read_points(tmp_path / "named.csv", Z).colors, rgb / 255.0, atol=1e-7)


def test_a_headerless_table_keeps_its_colours_by_position(tmp_path, rng):
    xyz = np.round(rng.normal(0, 1, (100, 3)) + [0, 0, 5], 6)
    rgb = rng.integers(0, 256, (100, 3))
    np.savetxt(tmp_path / "plain.xyz", np.c_[xyz, rgb], fmt=["%.6f"] * 3 + ["%d"] * 3)
    np.testing.assert_allclose(read_points(tmp_path / "plain.xyz", Z).colors, rgb / 255.0, atol=1e-7)


def test_one_stray_point_far_away_does_not_make_every_cell_hold_every_point(monkeypatch, rng):
    """Before: the first cell size came from the full extent (10 km / sqrt(N)), so the cells around
    every sampled point held all N points: samples x N distances (136 s on 1,000,000 points)."""
    n = 40_000
    pts = np.r_[rng.uniform([-5, -5, 0], [5, 5, 20], (n, 3)), [[10_000.0, 0.0, 0.0]]]
    measured: list[int] = []
    norm = np.linalg.norm

    def spy(a, *args, **kwargs):
        measured.append(len(a))
        return norm(a, *args, **kwargs)

    monkeypatch.setattr(np.linalg, "norm", spy)
    got = median_spacing(pts, np.random.default_rng(0), samples=200)
    monkeypatch.undo()
    assert sum(measured) < 100 * 200, sum(measured)  # before: about 200 x 40,000
    assert got == pytest.approx(_brute_force(pts, 0, 200), rel=1e-12)


@pytest.mark.parametrize("far", [1e9, 1e15])
def test_spacing_stays_exact_when_the_robust_extent_is_tiny_against_a_stray_point(far, rng):
    """The first cells are at least extent / 2**20, so cell indices fit int32 and keys int64."""
    pts = np.r_[rng.random((3000, 3)) * 1e-3, [[far, 0.0, 0.0]], [[0.0, far, far]]]
    h = pointio_spatial._first_cell_size(pts, len(pts), float(np.ptp(pts, axis=0).max()))
    assert h >= float(np.ptp(pts, axis=0).max()) / 2**20
    for seed in (0, 1):
        got = median_spacing(pts, np.random.default_rng(seed), samples=300)
        assert got == pytest.approx(_brute_force(pts, seed, 300), rel=1e-12)


def test_rows_with_a_trailing_comment_are_data(tmp_path):
    """Before: '1 2 3 # a' counted '#' and 'a' as non-numbers, so every row was a header line."""
    (tmp_path / "inline.xyz").write_text("1 2 3 # a\n4 5 6 # b\n7 8 9.5 # c\n")
    np.testing.assert_array_equal(
        read_points(tmp_path / "inline.xyz", Z).points, [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]]
    )
    (tmp_path / "named.txt").write_text("x y z # metres\n1 2 3 # first\n4 5 6\n")
    assert len(read_points(tmp_path / "named.txt", Z)) == 2
    assert sniff_not_points(tmp_path / "named.txt") is None
    (tmp_path / "rows.txt").write_text("1 2 3 # first point\n4 5 6 # second point\n")
    assert sniff_not_points(tmp_path / "rows.txt") is None  # before: "holds text without numbers"
    assert find_header([b"\n", b"# note\n", b"//x y z # m\n", b"1 2 3 # a\n"]) == (["x", "y", "z"], 3, 3)


def test_a_text_file_with_accents_named_npy_is_called_a_text_file(tmp_path):
    (tmp_path / "t.npy").write_text("x y z # hauteur en mètres, 20 °C\n1 2 3\n", encoding="utf-8")
    with pytest.raises(InputError, match="is a text file, not an .npy array"):
        read_points(tmp_path / "t.npy", Z)
    (tmp_path / "b.npy").write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match="does not start with numpy's .npy header"):
        read_points(tmp_path / "b.npy", Z)


def test_a_multi_block_leica_pts_file_is_read_whole(tmp_path, rng):
    """Before: 'line 5 has 1 values, expected 3' at the second block's count line."""
    a, b = np.round(rng.random((3, 4)) * 10, 3), np.round(rng.random((2, 4)) * 10, 3)

    def block(t):
        return [str(len(t))] + [" ".join(f"{v:.3f}" for v in row) for row in t]

    (tmp_path / "two.pts").write_text("\n".join(block(a) + block(b)) + "\n")
    np.testing.assert_allclose(read_points(tmp_path / "two.pts", Z).points, np.r_[a, b][:, :3])
    (tmp_path / "bad.pts").write_text("\n".join(block(a) + ["3"] + block(b)[1:]) + "\n")
    with pytest.raises(InputError, match=r"line 5: a \.pts block count of 3 points, but the block holds 2"):
        read_points(tmp_path / "bad.pts", Z)


def test_reader_sources_keep_lines_within_120_characters():
    root = Path(arboretum_library.__file__).parent
    for name in ("pointio.py", "pointio_formats.py", "pointio_text.py", "pointio_spatial.py", "pointio_up.py",
                 "pointio_ground.py", "pointio_wall.py"):
        long = [i + 1 for i, ln in enumerate((root / name).read_text().splitlines()) if len(ln) > 120]
        assert not long, (name, long)
