"""Bad and odd scan inputs (session 10): .npy look-alikes, huge coordinates, strict JSON, LAS colours,
classification columns."""

from __future__ import annotations

import argparse
import json

import laspy
import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from arboretum_library.cli import emit, main
from arboretum_library.errors import InputError
from arboretum_library.pointio import ReadOptions, read_points

Z = ReadOptions(up="z")


@pytest.fixture
def pts(rng):
    return rng.normal(0, 1, (300, 3)) + [0, 0, 5]


def _strict_json(text: str):
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


# ---------------------------------------------------------------- .npy look-alikes


def test_an_npz_named_npy_is_one_input_error(tmp_path, pts):
    path = tmp_path / "cloud.npy"
    with open(path, "wb") as f:
        np.savez(f, points=pts)
    with pytest.raises(InputError, match=r"cloud\.npy': is a zip archive \(an \.npz file\?\), not an \.npy array"):
        read_points(path)


def test_a_text_or_object_npy_says_what_it_is_not_without_pickle_advice(tmp_path):
    (tmp_path / "pts.npy").write_text("0 0 0\n1 1 1\n")
    (tmp_path / "junk.npy").write_bytes(bytes(range(256)))
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    for name, message in (
        ("pts.npy", r"is a text file, not an \.npy array \(a table of numbers\? name it \.xyz\)"),
        ("junk.npy", r"is not an \.npy array \(it does not start with numpy's \.npy header\)"),
        ("obj.npy", r"is an \.npy array of Python objects, not of numbers"),
    ):
        with pytest.raises(InputError, match=message) as info:
            read_points(tmp_path / name)
        assert "pickle" not in str(info.value)


# ---------------------------------------------------------------- huge coordinates, strict JSON


@pytest.mark.parametrize("suffix", [".xyz", ".npy"])
def test_coordinates_beyond_1e12_are_refused_when_read(tmp_path, pts, suffix):
    huge = np.r_[pts, [[1e308, 1e308, 1e308], [-1e308, -1e308, -1e308]]]
    path = tmp_path / f"huge{suffix}"
    np.save(path, huge) if suffix == ".npy" else np.savetxt(path, huge)
    with pytest.raises(InputError, match=r"coordinates up to 1e\+308, beyond 1e\+12 in any unit; a file read"):
        read_points(path)
    np.save(tmp_path / "utm.npy", pts * 1e11)  # 1e11 (geocentric millimetres): still read
    assert np.abs(read_points(tmp_path / "utm.npy", Z).points).max() > 1e11


def test_scan_info_json_of_a_huge_file_is_one_error_without_warnings(tmp_path, capsys):
    (tmp_path / "huge.xyz").write_text("0 0 0\n1e308 1e308 1e308\n-1e308 -1e308 -1e308\n")
    assert main(["scan", "info", str(tmp_path / "huge.xyz"), "--json"]) == 2
    out, err = capsys.readouterr()  # stdout: the error as JSON (session 18), strict
    assert err.count("\n") == 1 and "beyond 1e+12" in err
    assert json.loads(out) == {"command": "scan", "error": err.split("error: ", 1)[1].strip(), "exit": 2}


def test_emit_prints_strict_json_with_null_for_non_finite_numbers(capsys):
    data = {
        "a": float("inf"), "b": [1.5, float("nan"), -float("inf")], "c": np.array([np.inf, 2.0]),
        "d": np.float32("nan"), "e": (np.int64(3), "x"), "f": np.float64(0.25),
    }
    emit(argparse.Namespace(json=True), data, "text")
    got = _strict_json(capsys.readouterr().out)
    assert got == {"a": None, "b": [1.5, None, None], "c": [None, 2.0], "d": None, "e": [3, "x"], "f": 0.25}


# ---------------------------------------------------------------- LAS colours


def _las(path, point_format, rgb=None, classification=None):
    header = laspy.LasHeader(point_format=point_format, version="1.2")
    header.scales = [0.001] * 3
    las = laspy.LasData(header)
    rng = np.random.default_rng(0)
    las.x, las.y, las.z = rng.normal(0, 1, 200), rng.normal(0, 1, 200), rng.uniform(0, 10, 200)
    if rgb is not None:
        las.red, las.green, las.blue = rgb.T
    if classification is not None:
        las.classification = classification
    las.write(str(path))
    return path


def test_las_with_rgb_fields_all_zero_has_no_colours(tmp_path):
    assert read_points(_las(tmp_path / "zero.las", 3), Z).colors is None
    rgb = np.random.default_rng(1).integers(0, 65536, (200, 3)).astype(np.uint16)
    back = read_points(_las(tmp_path / "rgb.las", 3, rgb=rgb), Z)
    np.testing.assert_allclose(back.colors, rgb / 65535.0, atol=1e-7)


# ---------------------------------------------------------------- classification columns


def test_classification_columns_are_ignored_in_every_format_as_in_las(tmp_path, pts):
    asprs = np.where(np.arange(len(pts)) % 10 == 0, 2, 5)  # ground and high vegetation
    rows = [f"{x},{y},{z},{c}" for (x, y, z), c in zip(pts, asprs)]
    (tmp_path / "classified.csv").write_text("x,y,z,classification\n" + "\n".join(rows) + "\n")
    cloud = read_points(tmp_path / "classified.csv", Z)
    np.testing.assert_allclose(cloud.points, pts)
    assert cloud.labels is None and cloud.colors is None
    unassigned = [f"{x} {y} {z} 1" for x, y, z in pts]  # ASPRS 1 = unassigned: not "leaf"
    (tmp_path / "unassigned.txt").write_text("X Y Z Class\n" + "\n".join(unassigned) + "\n")
    assert read_points(tmp_path / "unassigned.txt", Z).labels is None
    table = np.zeros(len(pts), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("classification", "u1")])
    for k, name in enumerate("xyz"):
        table[name] = pts[:, k]
    table["classification"] = asprs
    PlyData([PlyElement.describe(table, "vertex")]).write(str(tmp_path / "c.ply"))
    assert read_points(tmp_path / "c.ply", Z).labels is None
    las = _las(tmp_path / "c.las", 0, classification=np.full(200, 5, np.uint8))
    assert read_points(las, Z).labels is None
    labelled = [f"{x},{y},{z},{c % 2}" for (x, y, z), c in zip(pts, asprs)]
    (tmp_path / "labelled.csv").write_text("x,y,z,label\n" + "\n".join(labelled) + "\n")
    np.testing.assert_array_equal(read_points(tmp_path / "labelled.csv", Z).labels, asprs % 2)
