"""Binary PLY reading (session 10): memory-mapped by plyfile, not read row by row; every format kept."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import plyfile
import pytest
from plyfile import PlyData, PlyElement

from arboretum_library.errors import InputError
from arboretum_library.pointio import ReadOptions, read_points, write_points

Z = ReadOptions(up="z")


@pytest.fixture
def cloud(rng):
    n = 500
    pts = rng.normal(0, 1, (n, 3)) + [0, 0, 5]
    return {
        "points": pts,
        "colors": (rng.integers(0, 256, (n, 3)) / 255.0).astype(np.float32),
        "labels": rng.integers(0, 2, n).astype(np.uint8),
        "branch_ids": rng.integers(-1, 9, n).astype(np.int32),
    }


def _no_row_by_row(monkeypatch):
    def refuse(self, stream, byte_order):
        raise AssertionError(f"element {self.name!r} read row by row")

    monkeypatch.setattr(plyfile.PlyElement, "_read_bin", refuse)


def test_binary_ply_is_not_read_row_by_row(tmp_path, cloud, monkeypatch):
    path = write_points(tmp_path / "c.ply", **cloud)
    _no_row_by_row(monkeypatch)
    back = read_points(path, Z)
    np.testing.assert_array_equal(back.points, cloud["points"])
    np.testing.assert_allclose(back.colors, cloud["colors"], atol=1e-7)
    np.testing.assert_array_equal(back.labels, cloud["labels"])
    np.testing.assert_array_equal(back.branch_ids, cloud["branch_ids"])


def test_big_endian_float32_ply_with_16_bit_colours(tmp_path, cloud, monkeypatch):
    n = len(cloud["points"])
    table = np.zeros(
        n, dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("red", ">u2"), ("green", ">u2"),
                  ("blue", ">u2"), ("label", "u1")],
    )
    for k, name in enumerate("xyz"):
        table[name] = cloud["points"][:, k]
    rgb16 = np.round(cloud["colors"].astype(np.float64) * 65535).astype(np.uint16)
    rgb16[0] = 65535  # beyond 0..255: only read right as 16 bits, whatever the byte order
    for k, name in enumerate(("red", "green", "blue")):
        table[name] = rgb16[:, k]
    table["label"] = cloud["labels"]
    path = tmp_path / "be.ply"
    PlyData([PlyElement.describe(table, "vertex")], byte_order=">").write(str(path))
    _no_row_by_row(monkeypatch)
    back = read_points(path, Z)
    np.testing.assert_array_equal(back.points, cloud["points"].astype(np.float32).astype(np.float64))
    np.testing.assert_allclose(back.colors, rgb16 / 65535.0, atol=1e-7)
    np.testing.assert_array_equal(back.labels, cloud["labels"])


def test_the_memory_map_is_released_after_reading(tmp_path, cloud, monkeypatch):
    """Nothing keeps the file mapped (on Windows it could then be neither replaced nor deleted)."""
    maps = []

    class Spy(np.memmap):
        def __new__(cls, *args, **kwargs):
            m = super().__new__(cls, *args, **kwargs)
            maps.append(weakref.ref(m))
            return m

    monkeypatch.setattr(np, "memmap", Spy)
    path = write_points(tmp_path / "c.ply", cloud["points"], labels=cloud["labels"])
    back = read_points(path, Z)
    gc.collect()
    assert len(maps) >= 1  # it was mapped
    assert all(ref() is None for ref in maps)
    path.unlink()
    np.testing.assert_array_equal(back.labels, cloud["labels"])


def test_ply_on_a_file_system_without_memory_maps(tmp_path, cloud, monkeypatch):
    path = write_points(tmp_path / "c.ply", cloud["points"], colors=cloud["colors"])
    monkeypatch.setattr(plyfile, "_can_mmap", lambda stream, mode="c": False)
    back = read_points(path, Z)
    np.testing.assert_array_equal(back.points, cloud["points"])
    np.testing.assert_allclose(back.colors, cloud["colors"], atol=1e-7)


def test_ascii_ply_and_a_mesh_with_faces(tmp_path, cloud):
    pts = cloud["points"][:20]
    vertex = np.zeros(20, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    for k, name in enumerate("xyz"):
        vertex[name] = pts[:, k]
    faces = np.zeros(3, dtype=[("vertex_indices", "i4", (3,))])
    faces["vertex_indices"] = [[0, 1, 2], [2, 3, 4], [5, 6, 7]]
    elements = [PlyElement.describe(vertex, "vertex"), PlyElement.describe(faces, "face")]
    for text in (True, False):
        path = tmp_path / f"mesh_{text}.ply"
        PlyData(elements, text=text).write(str(path))
        np.testing.assert_allclose(read_points(path, Z).points, pts, atol=1e-12 if not text else 1e-9)


def test_truncated_or_headless_ply_is_one_error(tmp_path, cloud):
    full = write_points(tmp_path / "full.ply", cloud["points"]).read_bytes()
    (tmp_path / "cut.ply").write_bytes(full[:-100])
    with pytest.raises(InputError, match=r"cut\.ply': is not a readable PLY file \(.*early end-of-file"):
        read_points(tmp_path / "cut.ply")
    (tmp_path / "novertex.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n")
    with pytest.raises(InputError, match=r"novertex\.ply': has no 'vertex' element"):
        read_points(tmp_path / "novertex.ply")
