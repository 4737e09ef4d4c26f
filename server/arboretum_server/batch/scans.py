"""Which files a build reads: ``expand_scans`` turns the SCAN arguments (files, folders) into scan files."""

from __future__ import annotations

from pathlib import Path

from arboretum_library.errors import InputError
from arboretum_library.pointio import READERS
from arboretum_library.pointio_text import sniff_not_points


def expand_scans(paths: list[str], ignored: list[tuple[str, str]] | None = None,
                 recursive: bool = False) -> list[str]:
    """Files as given; folders replaced by their point-cloud files (known suffixes), sorted, and with
    ``recursive`` those of every folder below too. Files that are recognisably not point clouds
    (``sniff_not_points``: a TreeQSM cylinder table, a licence) are left out and appended to ``ignored``
    as (path, why); so is, without ``recursive``, each subfolder holding point-cloud files.
    ``InputError`` for a path that does not exist, or when no scan is left."""
    out: list[str] = []
    left_out: list[tuple[str, str]] = []
    for p in paths:
        path = Path(p)
        if path.is_dir():
            files = _cloud_files(path, recursive)
            if not recursive:
                left_out += _subfolders_with_clouds(path)
        elif path.exists():
            files = [path]
        else:
            raise InputError(f"SCAN {p}: no such file or folder")
        for f in files:
            name, why = str(f) if path.is_dir() else str(p), sniff_not_points(f)
            if why is None:
                out.append(name)
            else:
                left_out.append((name, why))
    if not out:
        raise InputError(f"no scans given{_why_none(left_out)}")
    if ignored is not None:
        ignored.extend(left_out)
    return out


def _cloud_files(folder: Path, recursive: bool) -> list[Path]:
    found = folder.rglob("*") if recursive else folder.iterdir()
    return sorted(f for f in found if f.is_file() and f.suffix.lower() in READERS)


def _subfolders_with_clouds(folder: Path) -> list[tuple[str, str]]:
    """(subfolder, why) for each direct subfolder of ``folder`` with point-cloud files at any depth."""
    out = []
    for sub in sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith(".")):
        n = sum(sniff_not_points(f) is None for f in _cloud_files(sub, True))
        if n:
            out.append((str(sub), f"a subfolder with {n} point-cloud file{'s' * (n != 1)} "
                                  "(pass it too, or use --recursive)"))
    return out


def _why_none(left_out: list[tuple[str, str]]) -> str:
    subs = [p for p, why in left_out if why.startswith("a subfolder")]
    if subs:
        return (f": the folders hold no point-cloud files, but {len(subs)} subfolder"
                f"{'s' * (len(subs) != 1)} do ({', '.join(subs[:3])}{' ...' if len(subs) > 3 else ''}): "
                "pass them, or use --recursive")
    if left_out:
        return f": {left_out[0][0]} {left_out[0][1]}"
    return " (the folders hold no point-cloud files)"
