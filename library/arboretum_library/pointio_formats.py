"""Per-format readers and writers behind ``pointio.read_points`` / ``pointio.write_points``.

A reader takes a path and returns a ``Raw`` dict: ``points`` (N, 3) float64 (not yet checked for
finiteness), optional ``colors`` (N, 3) float in [0, 1], ``labels`` (N,) and ``branch_ids`` (N,), and
``resolution`` / ``stored_as`` (``coordinate_resolution``; absent for text: exact). Text
readers refuse NaN/infinite rows themselves, naming the line. A problem with the file raises
``InputError`` naming it. Writers take an open binary file and the validated arrays.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import ModuleType
from typing import Any, BinaryIO

import numpy as np

from .errors import InputError

Raw = dict[str, Any]

LABEL_NAMES = ("label", "labels", "scalar_label", "scalar_labels")
"""Columns holding our labels, 0 (wood) or 1 (leaf), first found first. CloudCompare writes a scalar
field ``Label`` to PLY as ``scalar_Label`` (names are compared in lower case)."""
CLASS_NAMES = ("classification", "class", "scalar_classification", "scalar_class")
"""Columns holding classes of another scheme (ASPRS LAS classes: 1 unassigned, 2 ground, 5 high
vegetation...; PDAL writes ``Classification``, CloudCompare ``scalar_Classification``): ignored in
every format, as LAS classification is. Read as labels they refused a classified CSV (class 5 is no
label), and a column of 0 (never classified) and 1 (unassigned) would have passed as wood and leaf.
Never looked up: listed so that no one adds them to ``LABEL_NAMES``."""
BRANCH_NAMES = ("branch_id", "branch_ids", "branchid", "branch")
COLOR_NAMES = (
    ("red", "green", "blue"),
    ("r", "g", "b"),
    ("diffuse_red", "diffuse_green", "diffuse_blue"),
)
MAX_HEADER_LINES = 100


def fail(path: Path, problem: str) -> InputError:
    """The one error a reader raises: ``'FILE': problem``."""
    return InputError(f"'{path}': {problem}")


# ---------------------------------------------------------------- attributes by name / by range


def scale_colors(rgb: np.ndarray, full: float | None = None) -> np.ndarray | None:
    """(N, 3) colours scaled to [0, 1]: as is when all lie in 0..1, /255 in 0..255, /``full``; else None."""
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.size == 0 or not np.isfinite(rgb).all() or rgb.min() < 0:
        return None
    top = float(rgb.max())
    for limit in (1.0, 255.0, full):
        if limit is not None and top <= limit:
            return (rgb / limit).astype(np.float32)
    return None


def from_named(path: Path, columns: dict[str, np.ndarray]) -> Raw:
    """A ``Raw`` cloud from columns named like PLY properties (x, y, z, red..., label, branch_id)."""
    cols = {k.lower(): v for k, v in columns.items()}
    if not all(k in cols for k in "xyz"):
        raise fail(path, f"needs x, y and z values, found {sorted(cols)}")
    raw: Raw = {"points": np.stack([np.asarray(cols[k], np.float64) for k in "xyz"], axis=1)}
    raw["resolution"], raw["stored_as"] = coordinate_resolution([np.asarray(cols[k]) for k in "xyz"])
    for names in COLOR_NAMES:
        if all(n in cols for n in names):
            kind = np.asarray(cols[names[0]]).dtype
            is_u16 = kind.kind == "u" and kind.itemsize == 2  # either byte order
            rgb = np.stack([cols[n] for n in names], axis=1)
            raw["colors"] = scale_colors(rgb, 65535.0 if is_u16 else None)
            break
    for key, names in (("labels", LABEL_NAMES), ("branch_ids", BRANCH_NAMES)):
        found = next((n for n in names if n in cols), None)
        if found is not None:
            raw[key] = integer_column(path, found, cols[found])
            if key == "labels":
                check_labels(path, raw["labels"], found)
    return raw


def coordinate_resolution(columns: list[np.ndarray]) -> tuple[float, str]:
    """The largest gap between neighbouring values the coordinate ``columns`` (x, y, z as stored) can
    hold over their range, and the name of their type: 0.0 for float64, 1.0 (one unit) for integers,
    and for float32 the spacing at the largest magnitude (0.5 m at 5.4e6 m, UTM northings; 3.1e-5 m at
    254 m). A float32 tree at UTM coordinates is read as if snapped to that grid: see
    ``pointio.precision_note``."""
    worst = 0.0
    for col in columns:
        kind = col.dtype
        if kind.kind in "iu":
            worst = max(worst, 1.0)
        elif kind.kind == "f" and kind.itemsize < 8 and col.size:
            top = max(abs(float(col.min())), abs(float(col.max())))
            if np.isfinite(top):  # NaN and infinite points are refused later, naming them
                worst = max(worst, float(np.spacing(kind.type(top))))
    return worst, "/".join(sorted({c.dtype.name for c in columns}))


def integer_column(path: Path, name: str, values: np.ndarray) -> np.ndarray:
    """``values`` as int64, or InputError when they are not whole numbers."""
    v = np.asarray(values)
    if v.dtype.kind == "f":
        if not np.isfinite(v).all() or (v != np.round(v)).any():
            raise fail(path, f"column '{name}' holds values that are not whole numbers")
    return v.astype(np.int64)


def check_labels(path: Path, labels: np.ndarray, name: str = "label") -> None:
    """InputError unless every label in column ``name`` is 0 (wood) or 1 (leaf): a column of other
    values (instance ids, another tool's classes) is refused, never read as wood and leaf."""
    bad = np.setdiff1d(np.unique(labels), [0, 1])
    if bad.size:
        shown = ", ".join(str(int(b)) for b in bad[:5])
        raise fail(path, f"labels must be 0 (wood) or 1 (leaf); found {shown} in column '{name}' (classes of "
                         "another scheme? rename that column 'classification' to read the points without it)")


def from_table(
    path: Path, table: np.ndarray, names: list[str] | None = None, rgb_at: int = 3, quoted_first: bool = False
) -> Raw:
    """A ``Raw`` cloud from an (N, C>=3) table; ``names`` from a header, if any (``header_columns``);
    ``quoted_first``: the file quoted the first value of its rows and not the next (R's row names).

    A header naming x, y and z names the colours too: only named colour columns count (a PDAL CSV's
    Intensity, ReturnNumber, NumberOfReturns are no colours). A header naming some of x, y, z never
    lets the first three columns stand in for them unless each named one is where it would be taken
    from (x first, y second, z third). Without such a header, colours are taken from columns
    ``rgb_at`` .. ``rgb_at + 2`` when their values all lie in 0..1 or 0..255.
    """
    raw: Raw = {"points": table[:, :3]}
    if names is not None and any(k in names for k in "xyz"):
        names = header_columns(path, names, table, quoted_first)
        if all(k in names for k in "xyz"):
            return from_named(path, dict(zip(names, table.T)))
        misplaced = [k for i, k in enumerate("xyz") if k in names and names.index(k) != i]
        if misplaced:
            missing = " and ".join(k for k in "xyz" if k not in names)
            raise fail(path, f"its header names no {missing} column, and its {', '.join(misplaced)} column is "
                             f"not where x, y, z would be taken from (header: {_shown(names)}); name all three")
        return raw
    if table.shape[1] >= rgb_at + 3:
        raw["colors"] = scale_colors(table[:, rgb_at : rgb_at + 3])
    return raw


def header_columns(path: Path, names: list[str], table: np.ndarray, quoted_first: bool = False) -> list[str]:
    """The header ``names`` one per column of ``table`` (``''``: unnamed), or InputError when x, y or z
    cannot be placed.

    Empty names after the last column (a delimiter ending the header line) are dropped. A header short
    of names over a first column of row names gets an unnamed first column (``_row_names``). Then
    columns past the names are unnamed (``x y z`` over rows with an intensity: read as x, y, z, the
    rest ignored, as before session 12) and names past the columns are dropped, unless they name x, y
    or z: that is refused, as is a header whose shift is ambiguous."""
    ncols = table.shape[1]
    names = list(names)
    while len(names) > ncols and names[-1] == "":
        names.pop()
    if len(names) < ncols and _row_names(path, names, table, quoted_first):
        names.insert(0, "")
    lost = [k for k in "xyz" if k in names[ncols:] and k not in names[:ncols]]
    if lost:
        where = ", ".join(f"{k} as column {names.index(k) + 1}" for k in lost)
        raise fail(path, f"its header names {where} but its rows hold {ncols} values (header: {_shown(names)}); "
                         "cannot tell which columns are x, y and z")
    return names[:ncols] + [""] * (ncols - len(names))


def _row_names(path: Path, names: list[str], table: np.ndarray, quoted: bool) -> bool:
    """Whether the first column of ``table``, whose header ``names`` are too few, holds row names, which
    R's ``write.table`` writes with no name over them: quoted (R quotes them, never numbers), or, one
    name short, whole numbers rising (``quote=FALSE``; by more than 1 after rows were dropped). One
    name short over distinct whole numbers that fall somewhere (unquoted row names of reordered rows,
    or x values?) is refused. Anything else is data (x of ``x y z`` over rows with an intensity)."""
    column = table[:, 0]
    if quoted:
        return True
    if len(names) != table.shape[1] - 1 or not (column == np.round(column)).all():
        return False
    if len(column) > 1 and (np.diff(column) > 0).all():
        return True
    if column.min() >= 0 and np.unique(column).size == column.size:
        raise fail(path, f"its header names {len(names)} columns ({_shown(names)}) over rows of "
                         f"{table.shape[1]} values, and its first column holds distinct whole numbers out of order: "
                         "row names (R's write.table) or data? Name every column in the header")
    return False


def _shown(names: list[str], limit: int = 8) -> str:
    shown = ", ".join(n or "(unnamed)" for n in names[:limit])
    return shown + (", ..." if len(names) > limit else "")


# ---------------------------------------------------------------- PLY, LAS/LAZ, NPY (text: pointio_text)


def read_ply(path: Path) -> Raw:
    """The vertex element of an ascii or binary PLY file (``from_named``: x y z, colours, labels...).

    Binary elements without list properties are memory-mapped by plyfile (copy-on-write; where the
    file system cannot map files plyfile reads them instead). On 1,000,000 binary vertices (x y z float,
    red green blue uchar) this function took 0.037 s against 6.6 s for plyfile's row-by-row reading
    (medians of 5 and 3 runs, session 10 review; docs/scan-input.md, Speed). The columns are copied
    out and the mapping dropped before the file is closed, so nothing keeps the file open or mapped
    afterwards (Windows could neither replace nor delete it).
    """
    from plyfile import PlyData

    try:
        with open(path, "rb") as f:
            ply = PlyData.read(f, mmap="c")
            vertex = ply["vertex"]
            columns = {p.name: np.array(vertex[p.name]) for p in vertex.properties}
            del ply, vertex  # the memory map goes with its last array
    except KeyError:
        raise fail(path, "has no 'vertex' element") from None
    except Exception as exc:  # plyfile raises many types for a corrupt file
        raise fail(path, f"is not a readable PLY file ({_short(exc)})") from None
    return from_named(path, columns)


LASPY_UNUSED = ("requests",)
"""Modules laspy imports only for what this module never does (``requests``: its COPC reader over HTTP,
in a ``try`` that leaves it None when missing); ``import_laspy`` keeps them out: ``requests`` and with it
urllib3, idna and charset_normalizer were 60-100 ms of ``arboretum decompose FILE.las`` (session 31)."""


def import_laspy() -> ModuleType:
    """laspy, imported the first time without ``LASPY_UNUSED`` (each ``None`` in ``sys.modules`` while laspy
    loads, so its ``import requests`` fails as if it were not installed; removed again after, so a later
    ``import requests`` works). A laspy that cannot do without one is imported again with it."""
    if "laspy" in sys.modules:
        return sys.modules["laspy"]
    kept_out = [m for m in LASPY_UNUSED if m not in sys.modules]
    for name in kept_out:
        sys.modules[name] = None  # type: ignore[assignment]  # what the import system reads as "not installed"
    try:
        import laspy
    except ModuleNotFoundError as exc:
        if exc.name not in kept_out:
            raise
        _let_in(kept_out)
        import laspy
    finally:
        _let_in(kept_out)
    return laspy


def _let_in(names: list[str]) -> None:
    """Undo ``import_laspy``'s blocking of ``names`` (a module imported for real since stays)."""
    for name in names:
        if name in sys.modules and sys.modules[name] is None:
            del sys.modules[name]


def read_las(path: Path) -> Raw:
    laspy = import_laspy()

    try:
        las = laspy.read(str(path))
        points = np.asarray(las.xyz, dtype=np.float64)
    except Exception as exc:  # laspy / lazrs raise many types for a corrupt file
        raise fail(path, f"is not a readable LAS/LAZ file ({_short(exc)})") from None
    if len(points) != las.header.point_count:
        raise fail(
            path,
            f"is truncated: its header promises {las.header.point_count} points, found {len(points)}",
        )
    scale = float(np.max(las.header.scales))
    raw: Raw = {"points": points, "resolution": scale, "stored_as": f"LAS integers scaled by {scale:g}"}
    dims = set(las.point_format.dimension_names)
    if {"red", "green", "blue"} <= dims:
        rgb = np.stack([np.asarray(las[c]) for c in ("red", "green", "blue")], axis=1)
        # a point format with RGB fields whose values are all 0 holds no colours (writers fill them
        # with zeros): read as colours, such a scan would turn black
        if rgb.size and rgb.max() > 0:
            raw["colors"] = scale_colors(rgb, 65535.0)
    return raw


NPY_MAGIC = b"\x93NUMPY"
ZIP_MAGIC = b"PK\x03\x04"


def read_npy(path: Path) -> Raw:
    with open(path, "rb") as f:
        magic = f.read(len(NPY_MAGIC))
    if magic.startswith(ZIP_MAGIC):
        raise fail(path, "is a zip archive (an .npz file?), not an .npy array")
    if magic != NPY_MAGIC:
        if _looks_like_text(path):
            raise fail(path, "is a text file, not an .npy array (a table of numbers? name it .xyz)")
        raise fail(path, "is not an .npy array (it does not start with numpy's .npy header)")
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as exc:  # truncated, or an object array
        if "allow_pickle" in str(exc):  # numpy's advice would be to run the file's code: never
            raise fail(path, "is an .npy array of Python objects, not of numbers") from None
        raise fail(path, f"is not a readable .npy array ({_short(exc)})") from None
    if arr.dtype.names:
        return from_named(path, {n: arr[n] for n in arr.dtype.names})
    if arr.ndim != 2 or arr.dtype.kind not in "fiu":
        raise fail(path, f"expected an (N, 3+) numeric array, got shape {arr.shape} of {arr.dtype}")
    if arr.shape[1] < 3:
        raise fail(path, f"has {arr.shape[1]} column(s); x, y and z need at least 3")
    raw = from_table(path, arr.astype(np.float64))
    raw["resolution"], raw["stored_as"] = coordinate_resolution([arr[:, k] for k in range(3)])
    return raw


CONTROL_BYTES = bytes(range(0, 9)) + bytes(range(14, 32)) + b"\x7f"
"""Bytes no text file holds (controls other than tab, line ends and form feed); binary data soon does."""


def _looks_like_text(path: Path, limit: int = 4096) -> bool:
    """Whether the first ``limit`` bytes of ``path`` are text: no ``CONTROL_BYTES``. Any byte from 128 up
    passes, so text with accents, degree signs or a BOM (UTF-8 or Latin-1) is text too."""
    with open(path, "rb") as f:
        head = f.read(limit)
    return bool(head) and len(head.translate(None, CONTROL_BYTES)) == len(head)


def _short(exc: Exception) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 120 else text[:117] + "..."


# ---------------------------------------------------------------- writers


def vertex_array(points, colors=None, labels=None, branch_ids=None) -> np.ndarray:
    """A structured (N,) array: x, y, z f8; red, green, blue u1; label u1; branch_id i4 (when given)."""
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    fields += [(c, "u1") for c in ("red", "green", "blue")] if colors is not None else []
    fields += [("label", "u1")] if labels is not None else []
    fields += [("branch_id", "<i4")] if branch_ids is not None else []
    out = np.zeros(len(points), dtype=fields)
    for k, name in enumerate("xyz"):
        out[name] = points[:, k]
    if colors is not None:
        rgb = np.round(np.asarray(colors, np.float64) * 255).astype(np.uint8)
        for k, name in enumerate(("red", "green", "blue")):
            out[name] = rgb[:, k]
    if labels is not None:
        out["label"] = labels
    if branch_ids is not None:
        out["branch_id"] = branch_ids
    return out


def write_ply(f: BinaryIO, table: np.ndarray) -> None:
    from plyfile import PlyData, PlyElement

    PlyData([PlyElement.describe(table, "vertex")], text=False, byte_order="<").write(f)


def write_npy(f: BinaryIO, table: np.ndarray) -> None:
    """Plain (N, 3) float64 for bare points; the structured array when there are attributes."""
    if len(table.dtype.names or ()) == 3:
        np.save(f, np.stack([table[n] for n in "xyz"], axis=1))
    else:
        np.save(f, table)


def write_text(f: BinaryIO, table: np.ndarray) -> None:
    """``x y z [red green blue] [label] [branch_id]``; a ``//`` header line when there are attributes."""
    names = list(table.dtype.names or ())
    if len(names) > 3:
        f.write(("//" + " ".join(names) + "\n").encode())
    fmt = ["%.6f"] * 3 + ["%d"] * (len(names) - 3)
    cols = np.column_stack([table[n].astype(np.float64) for n in names])
    np.savetxt(f, cols, fmt=fmt, delimiter=" ")
