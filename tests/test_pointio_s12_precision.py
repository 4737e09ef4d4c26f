"""Coordinate resolution of the stored type and ``precision_note`` (session 12).

A float32 PLY of a 1 cm tree at UTM coordinates (5.4e6 m, where float32 values are 0.5 m apart) was
decomposed into garbage without a word about precision.
"""

from __future__ import annotations

import laspy
import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from arboretum_library.errors import ValidationError
from arboretum_library.pointio import (
    PointCloud,
    ReadOptions,
    precision_note,
    read_points,
    write_points,
)

Z = ReadOptions(up="z")
UTM = np.array([500_000.0, 5_400_000.0, 300.0])


@pytest.fixture(scope="module")
def tree(scans_dir):
    """The rTwig coffee tree: 14,667 points, median spacing 9.7 mm, z 253.9 .. 257.6 m."""
    return np.loadtxt(scans_dir / "01_rtwig_coffeetree" / "01_rtwig_coffeetree.xyz")


def _ply(path, pts, dtype):
    v = np.zeros(len(pts), dtype=[(k, dtype) for k in "xyz"])
    for k, name in enumerate("xyz"):
        v[name] = pts[:, k]
    PlyData([PlyElement.describe(v, "vertex")]).write(str(path))
    return path


def test_float32_ply_at_utm_has_half_metre_resolution_and_a_note(tmp_path, tree):
    path = _ply(tmp_path / "utm.ply", tree + UTM, "f4")
    cloud = read_points(path, Z)
    assert (cloud.resolution, cloud.stored_as) == (0.5, "float32")
    note = precision_note(cloud)
    assert note is not None and "\n" not in note
    assert note.startswith(f"'{path}': coordinates stored as float32 at magnitudes up to 5.4e+06 m are only "
                           "0.5 m apart, coarser than a tenth of the median point spacing (")
    assert note.endswith("re-export it as float64, or shifted near the origin")


def test_float32_npy_at_utm(tmp_path, tree):
    np.save(tmp_path / "utm.npy", (tree + UTM).astype(np.float32))
    cloud = read_points(tmp_path / "utm.npy", Z)
    assert (cloud.resolution, cloud.stored_as) == (0.5, "float32")
    assert precision_note(cloud) is not None


def test_float32_structured_npy_and_binary_pcd(tmp_path, tree):
    pts = (tree + UTM).astype(np.float32)
    table = np.zeros(len(pts), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    for k, name in enumerate("xyz"):
        table[name] = pts[:, k]
    np.save(tmp_path / "s.npy", table)
    header = (f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {len(pts)}\nHEIGHT 1\n"
              f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\nDATA binary\n")
    (tmp_path / "b.pcd").write_bytes(header.encode() + pts.astype("<f4").tobytes())
    for name in ("s.npy", "b.pcd"):
        cloud = read_points(tmp_path / name, Z)
        assert (cloud.resolution, cloud.stored_as) == (0.5, "float32"), name


def test_float32_near_origin_and_float64_at_utm_give_no_note(tmp_path, tree):
    near = read_points(_ply(tmp_path / "near.ply", tree, "f4"), Z)
    assert near.resolution == 2.0**-15  # 3.05e-5 m: float32 spacing at 256-512 m (the top is at 257.6 m)
    assert precision_note(near) is None
    utm64 = read_points(_ply(tmp_path / "utm64.ply", tree + UTM, "f8"), Z)
    assert (utm64.resolution, utm64.stored_as) == (0.0, "float64")
    assert precision_note(utm64) is None


def test_text_and_in_memory_clouds_are_exact(tmp_path, tree):
    write_points(tmp_path / "t.xyz", tree + UTM)
    cloud = read_points(tmp_path / "t.xyz", Z)
    assert (cloud.resolution, cloud.stored_as) == (0.0, "text")
    assert precision_note(cloud) is None
    assert precision_note(PointCloud(points=tree)) is None


def test_las_resolution_is_its_largest_scale(tmp_path, tree):
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([0.01, 0.01, 0.001])
    header.offsets = UTM
    las = laspy.LasData(header)
    las.x, las.y, las.z = (tree + UTM).T
    las.write(str(tmp_path / "c.las"))
    cloud = read_points(tmp_path / "c.las", Z)
    assert cloud.resolution == 0.01 and cloud.stored_as == "LAS integers scaled by 0.01"
    note = precision_note(cloud)
    assert note is not None and "10 mm apart" in note and note.endswith("with a finer scale factor, or as float64 PLY")


def test_resolution_follows_scaling_and_the_threshold_is_a_tenth_of_the_spacing(tmp_path, tree):
    path = _ply(tmp_path / "utm.ply", tree + UTM, "f4")
    height = float(np.ptp(read_points(path, Z).points[:, 2]))
    scaled = read_points(path, ReadOptions(up="z", recentre=True, target_height=0.8))
    assert scaled.resolution == pytest.approx(0.5 * 0.8 / height)
    cloud = read_points(path, Z)
    assert precision_note(cloud, spacing=5.0) is None  # 0.5 m is exactly a tenth: no note
    assert precision_note(cloud, spacing=4.99) is not None


def test_resolution_must_be_a_number_at_least_zero(tree):
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValidationError, match="PointCloud.resolution: must be a number >= 0"):
            PointCloud(points=tree, resolution=bad)


def test_integer_ply_resolution_is_one_unit(tmp_path, tree):
    cloud = read_points(_ply(tmp_path / "mm.ply", np.round(tree * 100), "i4"), Z)  # centimetres
    assert (cloud.resolution, cloud.stored_as) == (1.0, "int32")
    assert precision_note(cloud, spacing=9.0) == (
        f"'{tmp_path / 'mm.ply'}': coordinates stored as int32 are only 1 m apart, coarser than a tenth of the "
        "median point spacing (9 m): the points sit on that grid; re-export it as float64")
    assert precision_note(cloud, spacing=10.0) is None


# ---------------------------------------------------------------- false positives (helper-96's review)


@pytest.fixture(scope="module")
def dense_las(tmp_path_factory):
    """/tmp/h96/las_note.py: a 0.15 m trunk 10 m tall, 400,000 points (2.24 mm apart) at UTM, 1 mm scale."""
    rng = np.random.default_rng(0)
    n = 400_000
    z, a = rng.uniform(0, 10, n), rng.uniform(0, 2 * np.pi, n)
    pts = np.c_[0.15 * np.cos(a), 0.15 * np.sin(a), z] + [512345.0, 5412345.0, 300.0]
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = [0.001] * 3, [512000, 5412000, 0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.T
    path = tmp_path_factory.mktemp("las") / "trunk.las"
    las.write(str(path))
    return read_points(path, Z)


def test_dense_las_with_a_1mm_scale_has_no_note_at_the_decomposition_budget(dense_las):
    """Before: the note at any budget (2.24 mm over all points); at 12,000 points they are 13 mm apart."""
    assert precision_note(dense_las, points=12_000) is None


def test_las_note_is_worded_by_its_scale_factor(dense_las):
    """Over all points (None or 0) the 1 mm grid is coarser than 0.224 mm; no UTM magnitude is named."""
    path = dense_las.source
    for points in (None, 0):
        assert precision_note(dense_las, points=points) == (
            f"'{path}': coordinates stored as LAS integers scaled by 0.001 are only 1 mm apart, coarser than a "
            "tenth of the median point spacing (2.24 mm): the points sit on that grid; re-export it with a finer "
            "scale factor, or as float64 PLY")
    assert precision_note(dense_las) == precision_note(dense_las, points=None)  # the callers' old call
    note = precision_note(dense_las, points=100_000)
    assert note is not None and "(4.47 mm at 100,000 points)" in note


def test_every_point_given_twice_gives_no_note(tmp_path, tree):
    """/tmp/h96/dup_note.py: float32 near the origin (0.24 um grid), two exports merged. Before: median
    spacing 0, so any grid was 'coarser'."""
    pts = tree - tree.min(axis=0)
    cloud = read_points(_ply(tmp_path / "dup.ply", np.r_[pts, pts], "f4"), Z)
    assert cloud.resolution == 2.0**-22
    assert precision_note(cloud) is None
    assert precision_note(cloud, points=12_000) is None


def test_one_distinct_point_gives_no_note():
    """(read_points refuses such a file; a cloud built in memory may hold it.)"""
    cloud = PointCloud(points=np.tile(UTM, (50, 1)), resolution=0.5, stored_as="float32")
    assert precision_note(cloud) is None
    assert precision_note(cloud, points=12_000) is None


def test_float32_utm_note_at_the_budget_names_it(tmp_path, tree):
    cloud = read_points(_ply(tmp_path / "utm.ply", tree + UTM, "f4"), Z)
    note = precision_note(cloud, points=12_000)
    assert note is not None and "at magnitudes up to 5.4e+06 m are only 0.5 m apart" in note
    assert " at 12,000 points): the points sit on that grid" in note
    assert note == precision_note(cloud, points=12_000)  # seeded
