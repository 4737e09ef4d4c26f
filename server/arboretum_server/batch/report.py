"""The build report: ``report.md``, ``report.json`` and PNG plots in one folder.

- ``curvature_lobes.png``: main-branch curvature against lobe count of every example in the library, one
  colour per species (VRTree Fig. 6, "Branch curvature and lobe number of HBL examples in our library").
- ``scan_seconds.png``: worker seconds per scan of this build (failed scans red).
- ``scan_examples.png``: examples per scan of this build.

Plots are drawn with Pillow (``plots.py``); without Pillow the report is the markdown and JSON alone.
Every file is written to a temporary name and renamed.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from arboretum_library.cli import counted

from .build import BuildResult

OK, FAILED = (44, 110, 180), (214, 39, 40)


def as_dict(result: BuildResult) -> dict[str, Any]:
    """The build as JSON-ready data (the ``--json`` output and ``report.json``)."""
    added = [r for r in result.records if r.status == "added"]
    busy = sum(r.seconds.get("total", 0.0) for r in result.records)
    return {
        "library": result.library, "cluster": result.cluster, "workers": result.workers,
        "wall_seconds": result.wall_seconds, "worker_seconds": busy,
        "scans": len(result.records), "added": len(added), "skipped": result.count("skipped"),
        "duplicate": result.count("duplicate"), "failed": result.count("failed"), "redone": result.redone,
        "examples_added": sum(len(r.examples) for r in added),
        "records": [{"path": r.path, "species": r.species, "status": r.status, "sha256": r.sha256,
                     "examples": r.examples, "error": r.error, "seconds": r.seconds,
                     "points": r.stats.get("points_read"), "notes": r.notes} for r in result.records],
        "ignored": [{"path": p, "why": why} for p, why in result.ignored],
        "notes": list(result.notes),
    }


def library_descriptors(library: str | os.PathLike) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{species: (lobe counts (N,), curvatures (N,) radians)} of every example in ``library``."""
    from arboretum_library.store import Library

    out: dict[str, tuple[list, list]] = {}
    with Library.open_reading(library) as lib:
        for e in lib.entries():
            lobes, curv = out.setdefault(e.species, ([], []))
            lobes.append(e.descriptors.lobe_count)
            curv.append(e.descriptors.curvature)
    return {s: (np.asarray(a, float), np.asarray(b, float)) for s, (a, b) in sorted(out.items())}


def write_report(result: BuildResult, folder: str | os.PathLike) -> dict[str, str]:
    """Write the report files into ``folder`` (created); returns {kind: path}."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    data = as_dict(result)
    written = {"json": _atomic(folder / "report.json", json.dumps(data, indent=2).encode())}
    plots = _plots(result, folder)
    written.update(plots)
    written["markdown"] = _atomic(folder / "report.md", markdown(data, plots).encode())
    return written


def _plots(result: BuildResult, folder: Path) -> dict[str, str]:
    try:
        from . import plots
    except ImportError:
        return {}
    try:
        import PIL  # noqa: F401
    except ImportError:
        return {}
    desc = library_descriptors(result.library)
    series = {s: (lobes, curv) for s, (lobes, curv) in desc.items()}
    images = {"curvature_lobes": plots.scatter(series, "Main-branch curvature and lobe count (VRTree Fig. 6)",
                                               "lobes per example", "curvature (rad)")}
    run = [r for r in result.records if r.status in ("added", "failed")]
    if run:
        colours = [FAILED if r.status == "failed" else OK for r in run]
        images["scan_seconds"] = plots.bars([r.seconds.get("total", 0.0) for r in run], colours,
                                            "Worker seconds per scan (red: failed)", "scan", "seconds")
        images["scan_examples"] = plots.bars([len(r.examples) for r in run], colours,
                                             "Examples per scan", "scan", "examples")
    out = {}
    for name, img in images.items():
        path = folder / f"{name}.png"
        out[name] = _atomic(path, _png(img))
    return out


def _png(img) -> bytes:
    import io

    buf = io.BytesIO()
    img.save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def markdown(data: dict[str, Any], plots: dict[str, str]) -> str:
    """The report as markdown text."""
    speed = data["worker_seconds"] / data["wall_seconds"] if data["wall_seconds"] > 0 else 0.0
    lines = [
        f"# Library build: {data['library']}", "",
        f"- cluster: {data['cluster'] or '(none needed)'}, {counted(data['workers'], 'worker')}",
        f"- scans: {data['scans']} given; {data['added']} added ({counted(data['examples_added'], 'example')}), "
        f"{data['skipped']} already in the library, {counted(data['duplicate'], 'duplicate')}, {data['failed']} failed"
        + (f"; {data['redone']} in the library done again (--rebuild, or damaged)" if data["redone"] else ""),
        f"- time: {data['wall_seconds']:.1f} s wall, {data['worker_seconds']:.1f} s of worker time "
        f"({speed:.2f}x)", *[f"- note: {_cell(n)}" for n in data.get("notes", [])], "",
    ]
    for name, title in (("curvature_lobes", "Curvature and lobes of every example in the library"),
                        ("scan_seconds", "Seconds per scan"), ("scan_examples", "Examples per scan")):
        if name in plots:
            lines += [f"![{title}]({Path(plots[name]).name})", ""]
    lines += ["| # | scan | species | status | examples | points | seconds | note |",
              "|---|---|---|---|---|---|---|---|"]
    for k, r in enumerate(data["records"], 1):
        secs = r["seconds"].get("total")
        note = "; ".join([r["error"]] if r["error"] else r["notes"])
        lines.append(f"| {k} | {_cell(Path(r['path']).name)} | {_cell(r['species'])} | {r['status']} | "
                     f"{len(r['examples'])} | {r['points'] if r['points'] is not None else ''} | "
                     f"{'' if secs is None else f'{secs:.2f}'} | {_cell(note)} |")
    if data.get("ignored"):
        lines += ["", "Left out (not point clouds, or subfolders not read):", ""]
        lines += [f"- {_cell(Path(i['path']).name)}: {_cell(i['why'])}" for i in data["ignored"]]
    return "\n".join(lines) + "\n"


def _cell(text: str) -> str:
    """``text`` on one line, its '|' escaped: a markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _atomic(path: Path, data: bytes) -> str:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return str(path)
