"""pointio: readers, writers, preparation options, up-axis detection, statistics, bad input."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import laspy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from plyfile import PlyData, PlyElement

from arboretum_library import pointio, pointio_pcd
from arboretum_library.assets import assets_dir
from arboretum_library.errors import InputError, ValidationError
from arboretum_library.geometry import yup_to_zup, zup_to_yup
from arboretum_library.model import LEAF, WOOD
from arboretum_library.pointio import (
    PointCloud,
    ReadOptions,
    even_sample_indices,
    guess_up_axis,
    median_spacing,
    read_points,
    scan_stats,
    trunk_base,
    write_points,
)

Z = ReadOptions(up="z")


def _tree(
    rng: np.random.Generator, n_trunk: int = 600, n_crown: int = 2400, crown_radius: float = 1.5
):
    """A toy tree (N, 3), Z up: a thin trunk 0..3 m and a ball-shaped crown around z = 4 m."""
    t = rng.uniform(0, 3, n_trunk)
    a = rng.uniform(0, 2 * np.pi, n_trunk)
    trunk = np.stack([0.1 * np.cos(a), 0.1 * np.sin(a), t], axis=1)
    d = rng.normal(size=(n_crown, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    crown = d * crown_radius * rng.uniform(0.6, 1.0, (n_crown, 1)) + [0, 0, 3 + crown_radius]
    return np.concatenate([trunk, crown]) + [10.0, -5.0, 100.0]


@pytest.fixture
def tree(rng) -> np.ndarray:
    return _tree(rng)


@pytest.fixture
def attrs(tree, rng):
    n = len(tree)
    return {
        "colors": (rng.integers(0, 256, (n, 3)) / 255.0).astype(np.float32),
        "labels": rng.integers(0, 2, n).astype(np.uint8),
        "branch_ids": rng.integers(-1, 40, n).astype(np.int32),
    }


# ---------------------------------------------------------------- round trips of the writable formats


@pytest.mark.parametrize("ext", [".ply", ".xyz", ".txt", ".npy"])
@pytest.mark.parametrize(
    "which", [(), ("colors",), ("labels", "branch_ids"), ("colors", "labels", "branch_ids")]
)
def test_write_read_round_trip(tmp_path, tree, attrs, ext, which):
    given_attrs = {k: attrs[k] for k in which}
    path = write_points(tmp_path / f"cloud{ext}", tree, **given_attrs)
    cloud = read_points(path, Z)
    tol = 1e-6 if ext in (".xyz", ".txt") else 0.0
    np.testing.assert_allclose(cloud.points, tree, atol=tol, rtol=0)
    for key in ("colors", "labels", "branch_ids"):
        got = getattr(cloud, key)
        if key not in which:
            assert got is None
        elif key == "colors":
            np.testing.assert_allclose(got, attrs[key], atol=1 / 510)
        else:
            np.testing.assert_array_equal(got, attrs[key])
    assert cloud.source == str(path) and cloud.up_axis == "z"
    assert [p.name for p in tmp_path.iterdir()] == [f"cloud{ext}"]  # no temporary files left


def test_write_accepts_a_point_cloud(tmp_path, tree, attrs):
    cloud = PointCloud(points=tree, labels=attrs["labels"])
    back = read_points(write_points(tmp_path / "c.ply", cloud), Z)
    np.testing.assert_array_equal(back.labels, attrs["labels"])
    assert back.colors is None


def test_write_is_atomic(tmp_path, tree, monkeypatch):
    path = write_points(tmp_path / "c.ply", tree[:10])
    before = path.read_bytes()

    def broken(f, table):
        f.write(b"ply\npartial")
        raise KeyboardInterrupt

    monkeypatch.setitem(pointio.WRITERS, ".ply", broken)
    with pytest.raises(KeyboardInterrupt):
        write_points(path, tree)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply"]


def test_write_bad_destination(tmp_path, tree):
    with pytest.raises(InputError, match=r"c\.obj.*writable: \.npy \.ply \.txt \.xyz"):
        write_points(tmp_path / "c.obj", tree)
    with pytest.raises(InputError, match="does not exist"):
        write_points(tmp_path / "nope" / "c.ply", tree)
    with pytest.raises(ValidationError, match="PointCloud.labels"):
        write_points(tmp_path / "c.ply", tree, labels=np.full(len(tree), 3))


# ---------------------------------------------------------------- formats we only read


def test_text_with_header_rgb255_and_label(tmp_path, tree, attrs):
    rgb = np.round(attrs["colors"] * 255).astype(int)
    rows = [
        f"{x:.6f},{y:.6f},{z:.6f},{r},{g},{b},{lab}"
        for (x, y, z), (r, g, b), lab in zip(tree, rgb, attrs["labels"])
    ]
    path = tmp_path / "scan.csv"
    path.write_text(
        "# exported by a scanner\nX,Y,Z,R,G,B,Label\n" + "\n".join(rows) + "\n"
    )
    cloud = read_points(path, Z)
    np.testing.assert_allclose(cloud.points, tree, atol=1e-6)
    np.testing.assert_allclose(cloud.colors, rgb / 255.0, atol=1e-7)
    np.testing.assert_array_equal(cloud.labels, attrs["labels"])


def test_text_without_header_rgb01_and_blank_lines(tmp_path, tree):
    col = np.linspace(0, 1, len(tree))
    table = np.column_stack([tree, col, col[::-1], np.full(len(tree), 0.5)])
    path = tmp_path / "scan.txt"
    path.write_text("\n".join(" ".join(f"{v:.6f}" for v in row) for row in table[:50]) + "\n\n\t\n")
    cloud = read_points(path, Z)
    assert len(cloud) == 50
    np.testing.assert_allclose(cloud.colors[:, 1], col[::-1][:50], atol=1e-6)


def test_pts_with_count_line_crlf_and_bom(tmp_path, tree, attrs):
    rgb = np.round(attrs["colors"][:30] * 255).astype(int)
    rows = [
        f"{x:.6f} {y:.6f} {z:.6f} {-900 + i} {r} {g} {b}"
        for i, ((x, y, z), (r, g, b)) in enumerate(zip(tree, rgb))
    ]
    (tmp_path / "s.pts").write_bytes(("\ufeff30\r\n" + "\r\n".join(rows) + "\r\n").encode("utf-8"))
    cloud = read_points(tmp_path / "s.pts", Z)
    np.testing.assert_allclose(cloud.points, tree[:30], atol=1e-6)
    np.testing.assert_allclose(cloud.colors, rgb / 255.0, atol=1e-7)


@pytest.mark.parametrize("sep", [" ", ",", ";", ", ", "\t"])
def test_text_separators_and_comments(tmp_path, sep):
    text = (
        f"x{sep}y{sep}z\n1{sep}2{sep}3\n# a comment\n\n4{sep}5{sep}6  # trailing\n7{sep}8{sep}9\n"
    )
    (tmp_path / "s.csv").write_text(text)
    np.testing.assert_array_equal(
        read_points(tmp_path / "s.csv", Z).points, [[1, 2, 3], [4, 5, 6], [7, 8, 9]]
    )
    (tmp_path / "nan.csv").write_text(text.replace("7", "nan"))
    with pytest.raises(
        InputError, match=r"1 point\(s\) have NaN or infinite values \(first on line 6\)"
    ):
        read_points(tmp_path / "nan.csv", Z)


def test_pcd_with_only_comments_after_data_line(tmp_path):
    (tmp_path / "c.pcd").write_text(
        _pcd_header(1, "x y z", "4 4 4", "F F F", "ascii") + "# nothing\n"
    )
    with pytest.raises(InputError, match=r"c\.pcd': holds no points"):
        read_points(tmp_path / "c.pcd")


def test_text_extra_columns_that_are_not_colours(tmp_path, tree):
    normals = np.tile([[0.0, -0.5, 0.8]], (len(tree), 1))
    np.savetxt(tmp_path / "n.asc", np.column_stack([tree, normals]), fmt="%.6f")
    cloud = read_points(tmp_path / "n.asc", Z)
    assert cloud.colors is None and len(cloud) == len(tree)


def test_ascii_ply_with_float_colours(tmp_path, tree, attrs):
    table = np.zeros(
        len(tree),
        [
            ("x", "f4"),
            ("y", "f4"),
            ("z", "f4"),
            ("red", "f4"),
            ("green", "f4"),
            ("blue", "f4"),
            ("label", "i4"),
            ("branch_id", "i2"),
        ],
    )
    for k, n in enumerate("xyz"):
        table[n] = tree[:, k]
    for k, n in enumerate(("red", "green", "blue")):
        table[n] = attrs["colors"][:, k]
    table["label"], table["branch_id"] = attrs["labels"], attrs["branch_ids"]
    PlyData([PlyElement.describe(table, "vertex")], text=True).write(str(tmp_path / "a.ply"))
    cloud = read_points(tmp_path / "a.ply", Z)
    np.testing.assert_allclose(cloud.points, tree.astype(np.float32), atol=1e-4)
    np.testing.assert_allclose(cloud.colors, attrs["colors"], atol=1e-6)
    np.testing.assert_array_equal(cloud.branch_ids, attrs["branch_ids"])


def _pcd_header(n: int, fields: str, size: str, kind: str, data: str) -> str:
    return (
        f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\n"
        f"TYPE {kind}\nCOUNT {' '.join('1' for _ in fields.split())}\nWIDTH {n}\nHEIGHT 1\n"
        f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )


def _packed_rgb(colors: np.ndarray) -> np.ndarray:
    rgb = np.round(colors * 255).astype(np.uint32)
    return ((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]).view(np.float32)


def test_pcd_binary_with_rgb_and_label(tmp_path, tree, attrs):
    n = len(tree)
    body = np.zeros(n, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<f4"), ("label", "<u4")])
    for k, name in enumerate("xyz"):
        body[name] = tree[:, k]
    body["rgb"], body["label"] = _packed_rgb(attrs["colors"]), attrs["labels"]
    head = _pcd_header(n, "x y z rgb label", "4 4 4 4 4", "F F F F U", "binary").encode()
    (tmp_path / "b.pcd").write_bytes(head + body.tobytes())
    cloud = read_points(tmp_path / "b.pcd", Z)
    np.testing.assert_allclose(cloud.points, tree.astype(np.float32))
    np.testing.assert_allclose(cloud.colors, attrs["colors"], atol=1e-6)
    np.testing.assert_array_equal(cloud.labels, attrs["labels"])
    (tmp_path / "t.pcd").write_bytes(head + body.tobytes()[:-7])
    with pytest.raises(InputError, match=r"t\.pcd.*truncated"):
        read_points(tmp_path / "t.pcd")


def test_pcd_ascii_and_compressed(tmp_path, tree, attrs):
    rgb = _packed_rgb(attrs["colors"][:20]).view(np.uint32)
    rows = "\n".join(f"{x:.5f} {y:.5f} {z:.5f} {c}" for (x, y, z), c in zip(tree[:20], rgb))
    (tmp_path / "a.pcd").write_text(
        _pcd_header(20, "x y z rgb", "4 4 4 4", "F F F U", "ascii") + rows + "\n"
    )
    cloud = read_points(tmp_path / "a.pcd", Z)
    np.testing.assert_allclose(cloud.points, tree[:20], atol=1e-5)
    np.testing.assert_allclose(cloud.colors, attrs["colors"][:20], atol=1e-6)
    (tmp_path / "nan.pcd").write_text(
        _pcd_header(2, "x y z", "4 4 4", "F F F", "ascii") + "1 2 3\nnan nan nan\n"
    )
    with pytest.raises(InputError, match=r"nan\.pcd.*1 point\(s\).*line 13"):
        read_points(tmp_path / "nan.pcd")
    (tmp_path / "c.pcd").write_bytes(
        _pcd_header(20, "x y z", "4 4 4", "F F F", "binary_compressed").encode() + b"\0" * 6
    )
    with pytest.raises(InputError, match=r"c\.pcd.*truncated"):
        read_points(tmp_path / "c.pcd")


def test_lzf_decompress_reference_vectors():
    lzf = pointio_pcd.lzf_decompress
    assert lzf(b"\x02abc", 3) == b"abc"
    assert lzf(b"\x02abc\x80\x02", 9) == b"abcabcabc"  # back reference overlapping its own output
    assert lzf(b"\x05abcdef\x20\x05", 9) == b"abcdefabc"  # plain back reference of 3 bytes
    assert lzf(b"\x00z\xe0\x0b\x00", 21) == b"z" * 21  # long back reference: 7 + 11 + 2 bytes


def test_lzf_pcd_with_fields_in_columns(tmp_path, tree):
    n = 40
    cols = b"".join(tree[:n, k].astype("<f4").tobytes() for k in range(3))
    chunks = [cols[i : i + 32] for i in range(0, len(cols), 32)]
    packed = b"".join(bytes([len(c) - 1]) + c for c in chunks)  # literal runs only: valid LZF
    head = _pcd_header(n, "x y z", "4 4 4", "F F F", "binary_compressed").encode()
    (tmp_path / "c.pcd").write_bytes(head + struct.pack("<II", len(packed), len(cols)) + packed)
    np.testing.assert_array_equal(
        read_points(tmp_path / "c.pcd", Z).points, tree[:n].astype(np.float32)
    )


@pytest.mark.parametrize("mode", ["ascii", "binary", "binary_compressed"])
def test_pcd_written_by_open3d(tmp_path, tree, attrs, mode):
    o3d = pytest.importorskip("open3d")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tree))
    pcd.colors = o3d.utility.Vector3dVector(attrs["colors"].astype(np.float64))
    path = str(tmp_path / "o3d.pcd")
    o3d.io.write_point_cloud(
        path, pcd, write_ascii=mode == "ascii", compressed=mode == "binary_compressed"
    )
    assert f"DATA {mode}\n".encode() in Path(path).read_bytes()[:400]
    cloud = read_points(path, Z)
    np.testing.assert_allclose(cloud.points, tree, rtol=1e-6)
    np.testing.assert_allclose(cloud.colors, attrs["colors"], atol=1 / 510)


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_las_and_laz_with_colours(tmp_path, tree, attrs, ext):
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = tree.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = tree[:, 0], tree[:, 1], tree[:, 2]
    rgb16 = np.round(attrs["colors"] * 65535).astype(np.uint16)
    las.red, las.green, las.blue = rgb16[:, 0], rgb16[:, 1], rgb16[:, 2]
    las.write(str(tmp_path / f"s{ext}"))
    cloud = read_points(tmp_path / f"s{ext}", Z)
    np.testing.assert_allclose(cloud.points, tree, atol=0.0006)
    np.testing.assert_allclose(cloud.colors, attrs["colors"], atol=1e-4)
    assert cloud.labels is None


def test_bundled_laz_matches_its_xyz(scans_dir):
    laz = read_points(scans_dir / "10_treels_pine" / "pine.laz", Z)
    xyz = read_points(scans_dir / "10_treels_pine" / "10_treels_pine.xyz", Z)
    assert len(laz) == len(xyz) == 73_851
    np.testing.assert_allclose(laz.points, xyz.points, atol=1e-4)


# ---------------------------------------------------------------- bad input: one InputError naming the file


def _bad_files(tmp: Path, tree: np.ndarray) -> dict[str, tuple[Path, str]]:
    out: dict[str, tuple[Path, str]] = {}

    def add(name: str, content: bytes | str, problem: str) -> None:
        path = tmp / name
        path.write_bytes(content.encode() if isinstance(content, str) else content)
        out[name] = (path, problem)

    add("empty.xyz", b"", "empty")
    add("header_only.csv", "x,y,z\n", "no points")
    add("nan.xyz", "# c\n1 2 3\n4 nan 6\n7 8 inf\n", r"2 point\(s\) have NaN or infinite.*line 3")
    add("two_cols.txt", "1 2\n3 4\n", "at least 3")
    add("one.xyz", "1 2 3\n", "exactly one point")
    add("same.xyz", "1 2 3\n1 2 3\n1 2 3\n", "all 3 points are identical")
    add("ragged.xyz", "1 2 3\n4 5 6 7\n", "line 2 has 4 values, expected 3")
    add("word.xyz", "1 2 3\n4 five 6\n", "line 2: 'five' is not a number")
    add(
        "labels.csv",
        "x,y,z,label\n0,0,0,0\n1,1,1,7\n",
        r"labels must be 0 \(wood\) or 1 \(leaf\); found 7",
    )
    add("junk.ply", b"not a ply at all\n\x00\x01", "not a readable PLY")
    add("junk.las", b"LASF" + b"\x00" * 50, "not a readable LAS/LAZ")
    add("junk.npy", b"\x93NUMPY garbage", "not a readable .npy")
    add("junk.pcd", b"hello\n", "no DATA line")
    add(
        "size.pcd",
        _pcd_header(2, "x y z", "3 3 3", "F F F", "ascii") + "1 2 3\n4 5 6\n",
        "malformed SIZE",
    )
    add(
        "count.pcd",
        _pcd_header(3, "x y z", "4 4 4", "F F F", "ascii") + "1 2 3\n4 5 6\n",
        "promises 3 points, the data holds 2",
    )
    add(
        "nox.pcd",
        _pcd_header(2, "a b c", "4 4 4", "F F F", "ascii") + "1 2 3\n4 5 6\n",
        "needs x, y and z",
    )
    add(
        "cols.pcd",
        _pcd_header(2, "x y z", "4 4 4", "F F F", "ascii") + "1 2 3 4\n4 5 6 7\n",
        "rows hold 4 values",
    )
    add("empty.npy", b"", "empty")
    add("obj.npy", b"", "")  # replaced below
    np.save(tmp / "obj.npy", np.zeros((4, 2)))
    out["obj.npy"] = (tmp / "obj.npy", "2 column")
    np.save(tmp / "flat.npy", np.zeros(9))
    out["flat.npy"] = (tmp / "flat.npy", r"expected an \(N, 3\+\) numeric array")
    np.save(tmp / "nan.npy", np.array([[0.0, 0, 0], [1, 1, np.nan]]))
    out["nan.npy"] = (tmp / "nan.npy", r"1 point\(s\).*first at index 1")
    write_points(tmp / "full.ply", tree)
    add("cut.ply", (tmp / "full.ply").read_bytes()[:-100], "not a readable PLY")
    np.save(tmp / "full.npy", tree)
    add("cut.npy", (tmp / "full.npy").read_bytes()[:-100], "not a readable .npy")
    pine = assets_dir() / "scans" / "10_treels_pine" / "pine.laz"
    add("cut.laz", pine.read_bytes()[: pine.stat().st_size // 2], "not a readable LAS/LAZ")
    laspy.read(pine).write(str(tmp / "full.las"))
    add(
        "cut.las",
        (tmp / "full.las").read_bytes()[:-1000],
        "truncated: its header promises 73851 points, found 73801",
    )
    return out


def test_bad_files_each_give_one_input_error(tmp_path, tree):
    for name, (path, problem) in _bad_files(tmp_path, tree).items():
        with pytest.raises(InputError, match=f"'{path}'.*{problem}") as info:
            read_points(path)
        assert "\n" not in str(info.value), name


def test_bad_paths(tmp_path):
    with pytest.raises(InputError, match=r"missing\.xyz': no such file"):
        read_points(tmp_path / "missing.xyz")
    (tmp_path / "d.ply").mkdir()
    with pytest.raises(InputError, match=r"d\.ply': is a folder"):
        read_points(tmp_path / "d.ply")
    (tmp_path / "s.obj").write_text("v 1 2 3\n")
    with pytest.raises(
        InputError,
        match=r"s\.obj': unknown point cloud format '\.obj' \(supported: .*\.las .*\.xyz\)",
    ):
        read_points(tmp_path / "s.obj")


def test_flat_cloud_cannot_be_scaled(tmp_path):
    (tmp_path / "flat.xyz").write_text("0 0 1\n1 0 1\n0 1 1\n")
    assert len(read_points(tmp_path / "flat.xyz", Z)) == 3
    with pytest.raises(InputError, match=r"flat\.xyz': cannot scale to a height"):
        read_points(tmp_path / "flat.xyz", ReadOptions(up="z", target_height=0.8))


def test_bad_options():
    with pytest.raises(InputError, match="up axis"):
        ReadOptions(up="x")
    with pytest.raises(InputError, match="height"):
        ReadOptions(target_height=0.0)
    with pytest.raises(InputError, match="max points"):
        ReadOptions(max_points=1)


def test_point_cloud_validates():
    pts = np.zeros((3, 3))
    with pytest.raises(ValidationError, match=r"PointCloud.points: expected shape \(N, 3\)"):
        PointCloud(points=np.zeros((3, 2)))
    with pytest.raises(ValidationError, match="PointCloud.colors: values must lie in"):
        PointCloud(points=pts, colors=np.full((3, 3), 1.5))
    with pytest.raises(
        ValidationError, match=r"PointCloud.branch_ids: expected shape \(3,\), got \(2,\)"
    ):
        PointCloud(points=pts, branch_ids=np.zeros(2))
    with pytest.raises(ValidationError, match="up_axis"):
        PointCloud(points=pts, up_axis="x")
    cloud = PointCloud(points=pts, labels=[WOOD, LEAF, LEAF])
    assert cloud.labels.dtype == np.uint8 and not cloud.points.flags.writeable


# ---------------------------------------------------------------- speed


def test_text_reading_is_fast(scans_dir):
    path = scans_dir / "10_treels_pine" / "10_treels_pine.xyz"
    best = min(_timed(lambda: read_points(path, Z)) for _ in range(3))
    assert best < 0.5


def test_two_million_point_npy(tmp_path):
    pts = np.random.default_rng(3).random((2_000_000, 3)) * [4, 4, 15]
    np.save(tmp_path / "big.npy", pts)
    t = _timed(lambda: read_points(tmp_path / "big.npy"))
    cloud = read_points(tmp_path / "big.npy")
    assert len(cloud) == 2_000_000 and cloud.up_axis == "z"
    assert t < 5.0


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


# ---------------------------------------------------------------- up axis


def test_up_axis_on_bundled_scans(scans_dir):
    scans = sorted(scans_dir.glob("*/*.xyz"))
    assert len(scans) == 4
    for path in scans:
        pts = read_points(path, Z).points
        axis, conf = guess_up_axis(pts)
        assert (axis, conf > 0.9) == ("z", True), path.name
        axis, conf = guess_up_axis(zup_to_yup(pts))
        assert (axis, conf > 0.9) == ("y", True), path.name


def test_auto_reads_a_y_up_file_back_to_z_up(tmp_path, scans_dir):
    pts = read_points(scans_dir / "06_adtree_tree7" / "06_adtree_tree7.xyz", Z).points
    write_points(tmp_path / "yup.npy", zup_to_yup(pts))
    cloud = read_points(tmp_path / "yup.npy")
    assert cloud.up_axis == "y"
    np.testing.assert_array_equal(cloud.points, pts)
    assert scan_stats(cloud)["up_guess"] == "y"


def test_auto_keeps_z_when_unsure(tmp_path, rng):
    """A box of noise a little longer along Y is no tree: 'auto' keeps the file as Z up."""
    pts = rng.random((5000, 3)) * [1.0, 1.2, 1.0]
    axis, confidence = guess_up_axis(pts)
    assert axis == "y" and confidence < pointio.AUTO_Y_CONFIDENCE  # measured 0.64
    write_points(tmp_path / "cube.npy", pts)
    cloud = read_points(tmp_path / "cube.npy")
    assert cloud.up_axis == "z"
    np.testing.assert_array_equal(cloud.points, pts)


def test_up_axis_of_a_flat_disc(rng):
    """A ground patch is flat: stood on its edge (the wrong axis) its footprint is a line, so it keeps its
    own up axis either way (it used to be stood upright: its thin edge read as a narrow foot)."""
    a, r = rng.uniform(0, 2 * np.pi, 20000), 5 * np.sqrt(rng.uniform(0, 1, 20000))
    disc = np.c_[r * np.cos(a), r * np.sin(a), rng.normal(0, 0.02, 20000)]
    assert guess_up_axis(disc)[0] == "z"
    axis, confidence = guess_up_axis(zup_to_yup(disc))
    assert axis == "y" and confidence > 0.99


def test_up_axis_wide_crown(rng):
    """A tree much wider than tall still stands on Z (the narrow trunk decides)."""
    pts = _tree(rng, n_trunk=1500, crown_radius=1.0)
    crown = pts[:, 2] > 103.0
    pts[crown] = (pts[crown] - [10.0, -5.0, 104.0]) * [5.0, 5.0, 1.2] + [10.0, -5.0, 104.0]
    width, height = np.ptp(pts[:, 0]), np.ptp(pts[:, 2])
    assert width > 1.8 * height  # 9.8 m wide, 5.2 m tall
    assert guess_up_axis(pts)[0] == "z"
    assert guess_up_axis(zup_to_yup(pts))[0] == "y"


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 20), st.just(3)), elements=st.floats(-1e6, 1e6)))
def test_y_to_z_round_trip(points):
    np.testing.assert_array_equal(yup_to_zup(zup_to_yup(points)), points)
    np.testing.assert_array_equal(zup_to_yup(yup_to_zup(points)), points)
    np.testing.assert_array_equal(yup_to_zup(points)[:, 2], points[:, 1])


# ---------------------------------------------------------------- preparation options


def test_recentre_puts_the_base_at_the_origin(tmp_path, scans_dir):
    path = scans_dir / "01_rtwig_coffeetree" / "01_rtwig_coffeetree.xyz"
    cloud = read_points(path, ReadOptions(up="z", recentre=True))
    z = cloud.points[:, 2]
    assert z.min() == 0.0
    slab = cloud.points[z <= 0.02 * np.ptp(z)]
    assert len(slab) >= 20
    np.testing.assert_allclose(np.median(slab[:, :2], axis=0), 0.0, atol=1e-12)
    assert (
        np.linalg.norm(slab[:, :2].mean(axis=0)) < 0.05
    )  # the trunk, not the crown, is at the origin


def test_trunk_base_ignores_a_stray_low_point(tree):
    stray = np.vstack([tree, tree[:1] + [3.0, 3.0, -0.5]])
    base = trunk_base(stray)
    np.testing.assert_allclose(base[:2], [10.0, -5.0], atol=0.15)
    assert base[2] == stray[:, 2].min()


@pytest.mark.parametrize("recentre", [False, True])
def test_target_height(scans_dir, recentre):
    path = scans_dir / "07_itsme_buttressed_tree_1" / "07_itsme_buttressed_tree_1.xyz"
    raw = read_points(path, Z)
    cloud = read_points(path, ReadOptions(up="z", recentre=recentre, target_height=0.8))
    assert np.ptp(cloud.points[:, 2]) == pytest.approx(0.8, abs=1e-12)
    ratio = np.ptp(cloud.points, axis=0) / np.ptp(raw.points, axis=0)
    np.testing.assert_allclose(ratio, 0.8 / np.ptp(raw.points[:, 2]), rtol=1e-12)
    if not recentre:  # scaled about the trunk base, which stays put
        np.testing.assert_allclose(trunk_base(cloud.points), trunk_base(raw.points), atol=1e-9)


def test_max_points_exact_deterministic_and_keeps_attributes(tmp_path, tree, attrs):
    write_points(tmp_path / "c.ply", tree, **attrs)
    a = read_points(tmp_path / "c.ply", ReadOptions(max_points=1000, seed=7))
    b = read_points(tmp_path / "c.ply", ReadOptions(max_points=1000, seed=7))
    c = read_points(tmp_path / "c.ply", ReadOptions(max_points=1000, seed=8))
    assert len(a) == 1000 and len(np.unique(a.points, axis=0)) == 1000
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.points, c.points)
    index = {tuple(p): i for i, p in enumerate(tree)}
    rows = np.array([index[tuple(p)] for p in a.points])
    np.testing.assert_array_equal(a.labels, attrs["labels"][rows])
    np.testing.assert_array_equal(a.branch_ids, attrs["branch_ids"][rows])
    assert len(read_points(tmp_path / "c.ply", ReadOptions(max_points=10**6))) == len(tree)


def _coverage(points: np.ndarray, sample: np.ndarray, size: float) -> float:
    cells = lambda p: {tuple(c) for c in np.floor((p - points.min(axis=0)) / size).astype(int)}  # noqa: E731
    return len(cells(sample)) / len(cells(points))


def test_max_points_is_spatially_even(scans_dir):
    pts = read_points(scans_dir / "10_treels_pine" / "10_treels_pine.xyz", Z).points
    rng = np.random.default_rng(0)
    even = pts[even_sample_indices(pts, 3000, rng)]
    rand = pts[rng.choice(len(pts), 3000, replace=False)]
    cov_even, cov_rand = _coverage(pts, even, 0.25), _coverage(pts, rand, 0.25)
    assert cov_even > 0.7 and cov_even > 1.3 * cov_rand  # measured 0.76 vs 0.49
    assert _coverage(pts, even, 0.5) > 0.88
    # the dense trunk is thinned more than the sparse crown: the sample's spacing is more uniform
    sp = [median_spacing(s, np.random.default_rng(1)) for s in (even, rand)]
    assert sp[0] > sp[1]


def test_even_sample_keeps_sparse_regions(rng):
    dense = rng.normal(size=(20_000, 3)) * 0.05
    sparse = rng.uniform(-5, 5, (200, 3)) + [20, 0, 0]
    idx = even_sample_indices(np.vstack([dense, sparse]), 400, rng)
    assert len(idx) == 400 and (np.diff(idx) > 0).all()
    assert (idx >= 20_000).sum() == 200  # every sparse point (each alone in its voxel) is kept


# ---------------------------------------------------------------- statistics


def test_median_spacing_matches_brute_force(rng):
    pts = np.vstack([rng.random((1500, 3)) * [1, 1, 10], rng.random((300, 3)) * 0.01])
    got = median_spacing(pts, np.random.default_rng(0), samples=5000)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert got == pytest.approx(np.median(d.min(axis=1)), rel=1e-12)


def test_scan_stats_values(tree, attrs):
    cloud = PointCloud(points=tree, labels=attrs["labels"], source="toy.ply")
    s = scan_stats(cloud)
    assert s["points"] == 3000 and s["file"] == "toy.ply"
    np.testing.assert_allclose(s["size"], np.ptp(tree, axis=0))
    assert s["height"] == pytest.approx(np.ptp(tree[:, 2]))
    np.testing.assert_allclose(s["min"], tree.min(axis=0))
    assert (s["up_axis"], s["up_guess"]) == ("z", "z") and s["up_confidence"] > 0.9
    assert (s["has_labels"], s["has_colors"], s["has_branch_ids"]) == (True, False, False)
    assert s["leaf_fraction"] == pytest.approx(attrs["labels"].mean())
    assert 0.005 < s["spacing"] < 0.2
