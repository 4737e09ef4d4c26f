"""Text tables as pandas and R write them, and CloudCompare's label columns (session 12).

pandas is not installed in .venv: the files are written here as pandas' ``DataFrame.to_csv()`` and R's
``write.csv`` / ``write.table`` defaults write them (checked against their documented output).
"""

from __future__ import annotations

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from arboretum_library.errors import InputError
from arboretum_library.pointio import ReadOptions, read_points
from arboretum_library.pointio_text import sniff_not_points

Z = ReadOptions(up="z")


@pytest.fixture
def pts(rng):
    return np.round(rng.normal(0, 1, (500, 3)) + [0, 0, 5], 5)


def _write(path, header, rows):
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _values(p, sep=",", quote=""):
    return sep.join(f"{quote}{v}{quote}" for v in p)


def test_pandas_to_csv_index_column_is_skipped(tmp_path, pts):
    """Before: ',x,y,z' lost its empty first name and the cloud was read as (index, x, y)."""
    path = _write(tmp_path / "pandas.csv", ",x,y,z", [f"{i},{_values(p)}" for i, p in enumerate(pts)])
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_r_write_csv_quoted_row_names_and_header(tmp_path, pts):
    """Before: '"1",...' was taken for text: 'holds no numeric rows in its first 100 lines'."""
    rows = [f'"{i + 1}",{_values(p)}' for i, p in enumerate(pts)]
    path = _write(tmp_path / "r.csv", '"","X","Y","Z"', rows)
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_r_write_table_header_one_name_short(tmp_path, pts):
    """R's write.table: blank separated, quoted, no name over the row names (which rise by more than 1
    after rows were dropped)."""
    rows = [f'"{3 * i + 1}" {_values(p, " ")}' for i, p in enumerate(pts)]
    path = _write(tmp_path / "r.txt", '"x" "y" "z"', rows)
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_quoted_numbers_and_columns_in_any_order(tmp_path, pts):
    rows = [_values(p[[2, 0, 1]], quote='"') for p in pts]
    path = _write(tmp_path / "q.csv", '"Z","X","Y"', rows)
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_pandas_index_with_columns_reordered_and_an_attribute(tmp_path, pts):
    rows = [f"{i},7,{_values(p[[1, 2, 0]])}" for i, p in enumerate(pts)]
    path = _write(tmp_path / "p.csv", ",intensity,Y,Z,X", rows)
    cloud = read_points(path, Z)
    np.testing.assert_array_equal(cloud.points, pts)
    assert cloud.colors is None


def test_trailing_delimiter_on_header_and_rows(tmp_path, pts):
    path = _write(tmp_path / "t.csv", "x,y,z,", [_values(p) + "," for p in pts])
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_header_naming_xyz_first_reads_those_columns_over_wider_rows(tmp_path, pts):
    """The header says x is the first column: it is, though a constant (not row names: they differ)."""
    path = _write(tmp_path / "m.csv", "x,y,z", [f"7,{_values(p)}" for p in pts])
    np.testing.assert_array_equal(read_points(path, Z).points, np.c_[np.full(len(pts), 7.0), pts[:, :2]])


# Over-wide rows (helper-96's review of session 12, /tmp/h96/csv): refused with "its header names 3 columns
# (x, y, z) but its rows hold 4 values", read as x, y, z before session 12.


def test_xyz_header_over_rows_with_an_intensity(tmp_path, pts):
    rows = [f"{_values(p, ' ')} {i % 500}" for i, p in enumerate(pts)]
    for name, header in (("i.txt", "x y z"), ("cc.txt", "//X Y Z"), ("c.csv", "x,y,z")):
        cloud = read_points(_write(tmp_path / name, header, rows if name != "c.csv" else
                                   [r.replace(" ", ",") for r in rows]), Z)
        np.testing.assert_array_equal(cloud.points, pts, err_msg=name)
        assert cloud.colors is None


def test_xyz_header_over_rows_with_three_more_columns(tmp_path, pts):
    """Unnamed trailing columns in 0..255 are no colours under a header naming x, y, z."""
    path = _write(tmp_path / "w.txt", "x y z", [f"{_values(p, ' ')} 10 20 30" for p in pts])
    cloud = read_points(path, Z)
    np.testing.assert_array_equal(cloud.points, pts)
    assert cloud.colors is None


def test_tab_separated_header_names_may_hold_spaces(tmp_path, pts):
    rows = [f"{_values(p, chr(9))}\t{i}" for i, p in enumerate(pts)]
    path = _write(tmp_path / "t.txt", "x\ty\tz\tpoint id", rows)
    np.testing.assert_array_equal(read_points(path, Z).points, pts)
    path = _write(tmp_path / "t2.txt", "point id\tx\ty\tz", [f"{i}\t{_values(p, chr(9))}" for i, p in enumerate(pts)])
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_r_write_table_after_its_rows_were_reordered(tmp_path, pts, rng):
    """Quoted row names are row names in any order. Before: refused as 3 names over 4 values."""
    order = rng.permutation(len(pts)) + 1
    rows = [f'"{k}" {_values(p, " ")}' for k, p in zip(order, pts)]
    path = _write(tmp_path / "r.txt", '"x" "y" "z"', rows)
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_unquoted_rising_row_numbers_under_a_header_one_short(tmp_path, pts):
    """R's write.table(quote=FALSE): the rising whole numbers are row names, as in session 12."""
    path = _write(tmp_path / "u.txt", "x y z", [f"{2 * i + 1} {_values(p, ' ')}" for i, p in enumerate(pts)])
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_unquoted_reordered_row_numbers_under_a_header_one_short_are_refused(tmp_path, pts, rng):
    order = rng.permutation(len(pts)) + 1
    path = _write(tmp_path / "a.txt", "x y z", [f"{k} {_values(p, ' ')}" for k, p in zip(order, pts)])
    with pytest.raises(InputError, match=r"a\.txt': its header names 3 columns \(x, y, z\) over rows of 4 values, "
                                         r"and its first column holds distinct whole numbers out of order: row names "
                                         r"\(R's write.table\) or data\? Name every column in the header"):
        read_points(path, Z)


def test_xyz_named_past_the_last_column_is_refused(tmp_path, pts):
    """Blank-separated names with a space ('point id') split in two: z would be the 5th of 4 columns."""
    path = _write(tmp_path / "p.txt", "point id x y z", [f"{i} {_values(p, ' ')}" for i, p in enumerate(pts)])
    with pytest.raises(InputError, match=r"p\.txt': its header names z as column 5 but its rows hold 4 values "
                                         r"\(header: point, id, x, y, z\); cannot tell which columns are x, y and z"):
        read_points(path, Z)


def test_header_longer_than_the_rows_past_xyz_reads_them(tmp_path, pts):
    path = _write(tmp_path / "l.txt", "x y z intensity", [_values(p, " ") for p in pts])
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_header_naming_some_of_xyz_out_of_place_is_refused(tmp_path, pts):
    """Before: 'id,x,y,height' read as (id, x, y)."""
    path = _write(tmp_path / "h.csv", "id,x,y,height", [f"{i},{_values(p)}" for i, p in enumerate(pts)])
    with pytest.raises(InputError, match=r"h\.csv': its header names no z column, and its x, y column is not"):
        read_points(path, Z)


def test_header_naming_some_of_xyz_in_place_reads_as_before(tmp_path, pts):
    path = _write(tmp_path / "e.csv", "x,y,elevation", [_values(p) for p in pts])
    np.testing.assert_array_equal(read_points(path, Z).points, pts)


def test_quoted_decimal_commas_are_refused(tmp_path):
    path = _write(tmp_path / "d.csv", '"x";"y";"z"', ['"1,25";"3,5";"7,0"', '"2,25";"4,5";"8,0"'])
    with pytest.raises(InputError, match=r"line 2: '1,25' looks like a number with a decimal comma"):
        read_points(path, Z)


def test_sniff_still_passes_index_tables(tmp_path, pts):
    path = _write(tmp_path / "pandas.csv", ",x,y,z", [f"{i},{_values(p)}" for i, p in enumerate(pts)])
    assert sniff_not_points(path) is None


# ---------------------------------------------------------------- label columns


def _ply(path, pts, extra: dict[str, np.ndarray]):
    fields = [(k, "f8") for k in "xyz"] + [(k, v.dtype.str) for k, v in extra.items()]
    v = np.zeros(len(pts), dtype=fields)
    for k, name in enumerate("xyz"):
        v[name] = pts[:, k]
    for name, values in extra.items():
        v[name] = values
    PlyData([PlyElement.describe(v, "vertex")]).write(str(path))
    return path


@pytest.mark.parametrize("name", ["scalar_label", "scalar_Label", "scalar_labels"])
def test_cloudcompare_scalar_label_is_read(tmp_path, pts, rng, name):
    """Before: CloudCompare's float 'scalar_label' was ignored without a word."""
    labels = (rng.random(len(pts)) < 0.3).astype(np.float32)
    cloud = read_points(_ply(tmp_path / "cc.ply", pts, {name: labels}), Z)
    assert cloud.labels is not None
    np.testing.assert_array_equal(cloud.labels, labels.astype(np.uint8))


def test_scalar_label_of_other_values_is_refused_naming_the_column(tmp_path, pts):
    labels = np.arange(len(pts), dtype=np.float32) % 4
    with pytest.raises(InputError, match=r"labels must be 0 \(wood\) or 1 \(leaf\); found 2, 3 in column "
                                         r"'scalar_label' \(classes of another scheme\? rename"):
        read_points(_ply(tmp_path / "cc.ply", pts, {"scalar_label": labels}), Z)


@pytest.mark.parametrize("name", ["scalar_Classification", "scalar_class", "Classification"])
def test_classification_columns_are_never_labels(tmp_path, pts, name):
    """ASPRS classes 0 (never classified) and 1 (unassigned) must not pass as wood and leaf."""
    classes = (np.arange(len(pts)) % 2).astype(np.uint8)
    assert read_points(_ply(tmp_path / "c.ply", pts, {name: classes}), Z).labels is None


def test_label_before_scalar_label(tmp_path, pts):
    ones, zeros = np.ones(len(pts), np.uint8), np.zeros(len(pts), np.float32)
    cloud = read_points(_ply(tmp_path / "b.ply", pts, {"scalar_label": zeros, "label": ones}), Z)
    assert cloud.labels is not None and cloud.labels.min() == 1


def test_a_pandas_tab_file_with_a_shuffled_index_is_read(tmp_path):
    """helper-99: pandas' to_csv(sep='\\t') writes the header '\\tx\\ty\\tz'; its leading tab was
    stripped, the empty index name lost, and a shuffled index refused as ambiguous."""
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(200, 3)) + [0, 0, 5]
    f = tmp_path / "p.txt"
    rows = ["\t".join([str(k)] + [f"{v:.6f}" for v in p]) for k, p in zip(rng.permutation(200), pts)]
    f.write_text("\tx\ty\tz\n" + "\n".join(rows) + "\n")
    assert np.allclose(read_points(f, ReadOptions(up="z")).points, pts, atol=1e-6)
