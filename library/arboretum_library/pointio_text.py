"""Text point clouds (.xyz .txt .csv .asc .pts) behind ``pointio.read_points``: the header read from
the first lines, the data streamed into ``np.loadtxt`` (the memory ``loadtxt`` needs, about the file
for x y z rows, not 8x), and whatever ``loadtxt`` refuses re-read line by line so an error names its
line. Also the sniffing that tells a point table from other tables (QSM cylinders) before a batch
reads it.
"""

from __future__ import annotations

import io
import re
import warnings
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .pointio_formats import MAX_HEADER_LINES, Raw, fail, from_table


def _is_number(token: bytes) -> bool:
    """Whether ``token`` is a number, in double quotes or not (R's ``write.csv`` quotes its row names:
    ``"1"``; numpy's parser takes double quotes only)."""
    try:
        float(token.strip(b'"'))
    except ValueError:
        return False
    return True


def _header_names(line: bytes) -> list[str]:
    """The lower-case column names of a header line, split at its commas, else its semicolons, else its
    tabs (a name may hold spaces: ``point id``), else its blanks, quotes removed. An empty name stays, as
    ``''``: the unnamed row-index column that pandas (``,x,y,z``) and R's ``write.csv``
    (``"","X","Y","Z"``) write first. Dropped, it shifted every name one column left and the cloud was
    read as (index, x, y)."""
    text = line.decode("utf-8", "replace").strip(" \r\n").lstrip("/#").strip(" ")  # a leading tab is a name
    sep = r"," if "," in text else r";" if ";" in text else r"\t" if "\t" in text else r"\s+"
    text = text if sep == r"\t" else text.strip()
    return [t.strip().strip("\"'").strip().lower() for t in re.split(sep, text)]


def read_text(path: Path) -> Raw:
    """Whitespace-, comma- or semicolon-separated rows; non-numeric lines before the data are a header.

    A first numeric line holding one number (the point count of Leica .pts files) is skipped, and in a
    .pts file so are the count lines of later blocks (``_drop_block_counts``). In a 7-column .pts file
    (x y z intensity r g b) the colours are columns 4-6, otherwise columns 3-5. Only the first lines are
    held as lines; the data are streamed into numpy's parser.
    """
    with open(path, "rb") as f:
        lines, whole = head_lines(f, MAX_HEADER_LINES + 1)
        bom = len(UTF8_BOM) if lines and lines[0].startswith(UTF8_BOM) else 0
        if bom:
            lines[0] = lines[0][bom:]
        names, first, count = find_header(lines[:MAX_HEADER_LINES])
        if first is None:
            many = len(lines) > MAX_HEADER_LINES or not whole
            raise fail(path, f"holds {'no numeric rows in its first 100 lines' if many else 'no points'}")
        start = first + 1 if count == 1 and first + 1 < len(lines) else first
        reason = not_points_reason(names)
        if reason:
            raise fail(path, reason)
        f.seek(bom + sum(len(ln) for ln in lines[:start]))
        table = parse_table(path, f, start + 1)
    rgb_at = 4 if path.suffix.lower() == ".pts" and table.shape[1] == 7 else 3
    raw = from_table(path, table, names, rgb_at, _quoted_first(lines[start : start + ROWS_CHECKED]))
    raw["resolution"], raw["stored_as"] = 0.0, "text"  # decimals as written: no type rounds them
    return raw


def find_header(lines: list[bytes]) -> tuple[list[str] | None, int | None, int]:
    """The column names of the header of ``lines`` (its last non-numeric line before the data, or None),
    the index of the first all-numeric line (None when there is none) and its number of values.
    Blank lines and ``#`` comments (whole lines or line ends) are skipped, so ``1 2 3 # a`` is data."""
    names = None
    for i, line in enumerate(lines):
        s = line.split(b"#", 1)[0].strip()
        if not s:
            continue
        tokens = [t for t in re.split(rb"[,;\s]+", s) if t]
        if all(_is_number(t) for t in tokens):
            return names, i, len(tokens)
        names = _header_names(line.split(b"#", 1)[0])  # unstripped: a leading tab is an empty first name
    return names, None, 0


def _quoted_first(rows: list[bytes]) -> bool:
    """Whether every data row of ``rows`` (the first ones) has its first value in double quotes and the
    next not: R's row names, which ``write.table`` quotes (numbers never), in any order once the rows
    were reordered."""
    seen = 0
    for row in rows:
        tokens = [t for t in re.split(rb"[,;\s]+", row.split(b"#", 1)[0].strip()) if t]
        if not tokens:
            continue
        if len(tokens) < 2 or not tokens[0].startswith(b'"') or tokens[1].startswith(b'"'):
            return False
        seen += 1
    return seen > 0


UTF8_BOM = b"\xef\xbb\xbf"
HEAD_BYTES = 1 << 16
"""Bytes ``head_lines`` reads at first (it reads more while it has too few lines)."""


def head_lines(f: BinaryIO, count: int) -> tuple[list[bytes], bool]:
    """Up to the first ``count`` complete lines of ``f`` from where it stands, with their line ends,
    and whether they are all its lines. Leaves ``f`` where it was."""
    begin, data = f.tell(), b""
    while True:
        size = max(HEAD_BYTES, len(data))
        chunk = f.read(size)
        data, whole = data + chunk, len(chunk) < size
        lines = data.splitlines(keepends=True)
        if whole or len(lines) > count:
            break
    f.seek(begin)
    if not whole:
        lines = lines[:-1]  # may be cut short (or a \r\n cut in two)
    return lines[:count], whole and len(lines) <= count


CYLINDER_COLUMNS = ("start_x", "axis_x", "length", "radius")
"""Header columns of a cylinder model (TreeQSM's exported ``QSM.cylinder``), not of a point cloud."""
TEXT_SUFFIXES = (".xyz", ".txt", ".csv", ".asc", ".pts")
"""Suffixes read by ``read_text``."""


def not_points_reason(names: list[str] | None) -> str | None:
    """Why a text table with header ``names`` is recognisably not a point cloud (a cylinder table:
    start or axis columns and a radius, without x, y, z), else None."""
    if not names or all(k in names for k in "xyz"):
        return None
    if "radius" in names and ("start_x" in names or "axis_x" in names):
        return (f"is a cylinder table ({', '.join(CYLINDER_COLUMNS)}: e.g. a TreeQSM model), "
                "not a point cloud")
    return None


def sniff_not_points(path: Path, limit: int = 65536) -> str | None:
    """Why a text file is recognisably not a point cloud (``not_points_reason`` of its header, or prose
    without numbers), from its first ``limit`` bytes only: cheap enough to sort the files of a folder.
    None for other formats, for files that cannot be read and for anything else (``read_text`` judges)."""
    if path.suffix.lower() not in TEXT_SUFFIXES:
        return None
    try:
        with open(path, "rb") as f:
            data = f.read(limit)
        lines = data.removeprefix(UTF8_BOM).splitlines()
    except OSError:
        return None
    names, first, _ = find_header(lines[:MAX_HEADER_LINES])
    if first is not None:
        return not_points_reason(names)
    # read_text refuses it too; a short .txt of prose (a README beside the scans) is no scan either,
    # while a short broken .xyz stays a scan that fails, so its user hears of it
    short_prose = path.suffix.lower() == ".txt" and 0 < len(data) < limit
    short_prose = short_prose and any(re.search(rb"[A-Za-z]{3,}", ln) for ln in lines)
    if len(lines) > MAX_HEADER_LINES or short_prose:
        return f"holds text without numbers in its first {MAX_HEADER_LINES} lines (e.g. a licence), not a point cloud"
    return None


def parse_table(path: Path, f: BinaryIO, first_line: int) -> np.ndarray:
    """The numbers of ``f`` from where it stands (that is line ``first_line``) as an (R, C>=3) float64
    table.

    numpy's C parser (``np.loadtxt``) streams well-formed data, with the delimiter of the first rows;
    anything it refuses is read whole and parsed again with commas and semicolons as spaces, then if
    need be line by line to say what is wrong where. Rows with NaN or infinite values are refused with
    their line.
    """
    begin = f.tell()
    rows = [r.split(b"#", 1)[0] for r in head_lines(f, 4 * ROWS_CHECKED)[0]]
    _refuse_decimal_commas(path, rows, first_line)
    sample = b"".join(rows)
    quoted = b'"' in sample  # R's write.csv quotes row names, PDAL and spreadsheets may quote numbers
    table = _loadtxt(f, "," if b"," in sample else ";" if b";" in sample else None, quoted)
    if table.shape[1] < 3 or not len(table):
        f.seek(begin)
        body = f.read()
        table = _loadtxt(io.BytesIO(_as_blanks(body)), None)
        if table.shape[1] < 3 or not len(table):
            table = _parse_carefully(path, _rows(body), first_line)
    bad = ~np.isfinite(table).all(axis=1)
    if bad.any():
        f.seek(begin)
        numbers = [first_line + i for i, r in enumerate(_rows(f.read())) if r.strip()]
        raise fail(
            path,
            f"{int(bad.sum())} point(s) have NaN or infinite values (first on line {numbers[int(np.argmax(bad))]})",
        )
    return table


def _loadtxt(f: BinaryIO, delimiter: str | None, quoted: bool = False) -> np.ndarray:
    """``np.loadtxt`` of a binary stream (numbers are ASCII: latin-1 decodes any byte), or an empty
    (0, 0) table when it refuses the data. ``quoted``: values may be in double quotes."""
    text = io.TextIOWrapper(f, encoding="latin-1")
    try:
        with warnings.catch_warnings():  # "input contained no data": said by the caller, as an InputError
            warnings.simplefilter("ignore", UserWarning)
            return np.loadtxt(text, delimiter=delimiter, ndmin=2, quotechar='"' if quoted else None)
    except ValueError:
        return np.zeros((0, 0))
    finally:
        text.detach()  # leave ``f`` open


DECIMAL_COMMA = re.compile(rb"[-+]?\d+,\d+(?:[eE][-+]?\d+)?")
"""A number written with a decimal comma, e.g. ``-1,234`` or ``5,6e-3``."""
QUOTED_DECIMAL_COMMA = re.compile(rb'"(' + DECIMAL_COMMA.pattern + rb')"')
"""The same in double quotes (``"1,25","3,5"``): one value, never two columns."""
ROWS_CHECKED = 20
"""Data rows ``_refuse_decimal_commas`` looks at."""


def _refuse_decimal_commas(path: Path, lines: list[bytes], first_line: int) -> None:
    """InputError when a row's values are separated by spaces, tabs or semicolons and written with
    decimal commas (``1,25 3,5 7,0`` or ``1,25;3,5;7,0``): read as comma-separated columns they would
    become twice as many whole numbers. So are quoted ones in any row (``"1,25","3,5","7,0"``).
    Comma-separated rows (``1.25,3.5,7.0``, ``1, 2, 3``, ``"1.25","3.5","7.0"``) pass."""
    seen = 0
    for i, line in enumerate(lines):
        row = line.split(b"#", 1)[0]
        tokens = [t for t in re.split(rb"[;\s]+", row) if t]
        if not tokens:
            continue
        commas = [t for t in tokens if DECIMAL_COMMA.fullmatch(t)]
        quoted = QUOTED_DECIMAL_COMMA.search(row)
        if quoted or (len(tokens) >= 3 and commas and all(b"," not in t or t in commas for t in tokens)):
            example = (quoted.group(1) if quoted else commas[0]).decode("utf-8", "replace")
            raise fail(path, f"line {first_line + i}: '{example}' looks like a number with a decimal comma; "
                             "decimal commas? convert them to points (e.g. sed 's/,/./g') and read it again")
        seen += 1
        if seen >= ROWS_CHECKED:
            return


def _as_blanks(body: bytes) -> bytes:
    """``body`` with commas, semicolons and double quotes turned to spaces."""
    for char in (b",", b";", b'"'):
        if char in body:
            body = body.replace(char, b" ")
    return body


def _rows(body: bytes) -> list[bytes]:
    """The lines of ``body`` with delimiters and quotes turned to spaces and ``#`` comments removed."""
    body = _as_blanks(body)
    rows = body.splitlines()
    return [r.split(b"#", 1)[0] for r in rows] if b"#" in body else rows


def _parse_carefully(path: Path, rows: list[bytes], first_line: int) -> np.ndarray:
    """The table of ``rows``, or InputError naming the first line that is wrong and how."""
    counts = np.array([len(r.split()) for r in rows], dtype=np.int64)
    if path.suffix.lower() == ".pts":
        _drop_block_counts(path, rows, counts, first_line)
    keep = np.flatnonzero(counts > 0)
    if not keep.size:
        raise fail(path, "holds no points")
    ncols = int(counts[keep[0]])
    if ncols < 3:
        raise fail(
            path, f"line {first_line + keep[0]} has {ncols} column(s); x, y and z need at least 3"
        )
    ragged = keep[counts[keep] != ncols]
    if ragged.size:
        i = int(ragged[0])
        raise fail(
            path,
            f"line {first_line + i} has {counts[i]} values, expected {ncols} like line {first_line + keep[0]}",
        )
    try:
        tokens = b" ".join(rows).split()
        values = np.fromiter(map(float, tokens), dtype=np.float64, count=len(tokens))
    except ValueError:
        i, token = next((i, t) for i, r in enumerate(rows) for t in r.split() if not _is_number(t))
        raise fail(
            path, f"line {first_line + i}: '{token.decode('utf-8', 'replace')}' is not a number"
        ) from None
    return values.reshape(-1, ncols)


def _drop_block_counts(path: Path, rows: list[bytes], counts: np.ndarray, first_line: int) -> None:
    """Blank out (in place) the point-count lines that start the second and later blocks of a
    multi-block Leica .pts file (count, rows, count, rows...; ``read_text`` skips the first count):
    one whole number each, which must equal the number of rows up to the next count line."""
    single = np.flatnonzero(counts == 1)
    if not single.size or int(counts.max()) < 3:
        return
    ends = np.r_[single[1:], len(rows)]
    for i, end in zip(single, ends):
        text = rows[i].strip().decode("latin-1")
        held = int(np.count_nonzero(counts[i + 1 : end]))
        if not text.isdigit() or int(text) != held:
            raise fail(path, f"line {first_line + i}: a .pts block count of {text} points, but the block "
                             f"holds {held} rows (a multi-block Leica .pts file repeats count and rows)")
        rows[i], counts[i] = b"", 0
