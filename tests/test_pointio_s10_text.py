"""Text point clouds (session 10): streamed into numpy's parser, with every line number still right."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from arboretum_library import pointio_text
from arboretum_library.errors import InputError
from arboretum_library.pointio import ReadOptions, read_points
from arboretum_library.pointio_text import read_text

Z = ReadOptions(up="z")


@pytest.fixture
def pts(rng):
    return np.round(rng.normal(0, 1, (4000, 3)) + [0, 0, 5], 6)


def _rows(points, sep=" "):
    return [sep.join(f"{v:.6f}" for v in p) for p in points]


def test_text_reader_holds_about_the_table_not_8_times_the_file(tmp_path, rng):
    """Before: the bytes, a list of every line and their join (about 8x the file at peak)."""
    path = tmp_path / "big.xyz"
    np.savetxt(path, rng.random((100_000, 3)) * 10, fmt="%.6f")
    tracemalloc.start()
    try:
        table = read_text(path)["points"]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert table.shape == (100_000, 3)
    assert peak < 2.0 * path.stat().st_size, peak / path.stat().st_size


def test_errors_far_into_the_file_name_their_line(tmp_path, pts, monkeypatch):
    monkeypatch.setattr(pointio_text, "HEAD_BYTES", 256)  # head and data in many reads
    rows = ["// x y z", "# a comment"] + _rows(pts)
    cases = {
        "nan.xyz": (2500, "nan 1 2", r"1 point\(s\) have NaN or infinite values \(first on line 2503\)"),
        "ragged.xyz": (3000, "1 2 3 4", r"line 3003 has 4 values, expected 3 like line 3"),
        "word.xyz": (3500, "1 two 3", r"line 3503: 'two' is not a number"),
    }
    for name, (i, bad, message) in cases.items():
        lines = list(rows)
        lines[i + 2] = bad
        (tmp_path / name).write_text("\r\n".join(lines) + "\r\n")
        with pytest.raises(InputError, match=message):
            read_points(tmp_path / name, Z)


def test_mixed_delimiters_byte_order_mark_and_old_mac_line_ends(tmp_path, pts, monkeypatch):
    monkeypatch.setattr(pointio_text, "HEAD_BYTES", 128)
    space, comma = _rows(pts[:2000]), _rows(pts[2000:], sep=",")
    (tmp_path / "mixed.csv").write_bytes(
        b"\xef\xbb\xbfx y z\n" + ("\n".join(space + comma) + "\n").encode()
    )
    np.testing.assert_allclose(read_points(tmp_path / "mixed.csv", Z).points, pts)
    trailing = [r + "," for r in _rows(pts, sep=",")]  # a delimiter at every line end
    (tmp_path / "trailing.csv").write_text("\n".join(trailing) + "\n")
    np.testing.assert_allclose(read_points(tmp_path / "trailing.csv", Z).points, pts)
    (tmp_path / "mac.xyz").write_bytes(("\r".join(["x y z", *_rows(pts)]) + "\r").encode())
    np.testing.assert_allclose(read_points(tmp_path / "mac.xyz", Z).points, pts)
    (tmp_path / "bom.xyz").write_bytes(b"\xef\xbb\xbf" + ("\n".join(_rows(pts)) + "\n").encode())
    np.testing.assert_allclose(read_points(tmp_path / "bom.xyz", Z).points, pts)


def test_long_headers_and_point_counts(tmp_path, pts, monkeypatch):
    monkeypatch.setattr(pointio_text, "HEAD_BYTES", 64)
    long = ["# " + "c" * 500] * 30 + ["x y z"]
    (tmp_path / "long.xyz").write_text("\n".join(long + _rows(pts)) + "\n")
    np.testing.assert_allclose(read_points(tmp_path / "long.xyz", Z).points, pts)
    (tmp_path / "count.pts").write_text("\n".join([str(len(pts)), *_rows(pts)]) + "\n")
    np.testing.assert_allclose(read_points(tmp_path / "count.pts", Z).points, pts)
    (tmp_path / "prose.xyz").write_text("\n".join(["words only"] * 150) + "\n")
    with pytest.raises(InputError, match="no numeric rows in its first 100 lines"):
        read_points(tmp_path / "prose.xyz")
    (tmp_path / "comma.xyz").write_text("\n".join(["1,5 2,5 3,5"] * 30) + "\n")
    with pytest.raises(InputError, match="decimal comma"):
        read_points(tmp_path / "comma.xyz")
