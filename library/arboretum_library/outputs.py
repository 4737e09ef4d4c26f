"""Output paths checked before any work: one clear error instead of a lost input or a late failure.

Every command that writes a file calls ``check_output`` on each output path while it parses its
arguments, before it reads or computes anything. It refuses:

- a path that is an existing folder, or whose folder is missing, is a file, or cannot be written;
- a path that is the same file as one of the command's inputs (``render h.npz --out h.npz`` turned
  the record into a PNG) or as another of its outputs (``grow --out m.ply --skeleton m.ply``);
- a suffix the command does not write, when it names the suffixes it does;
- a path inside a library the command uses (``libraries``): ``assemble --out LIB/examples/X/arrays.npz``
  replaced an example's arrays with a session file.

Writers still write to a temporary file and rename it (``codec.save_record``); this only moves the
errors a user can cause to the start and names the path the user gave, not the temporary file.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from .errors import InputError

PathLike = str | os.PathLike


def check_output(path: PathLike, what: str = "--out", *, inputs: Iterable[PathLike | None] = (),
                 outputs: Iterable[PathLike | None] = (), suffixes: Iterable[str] = (),
                 libraries: Iterable[PathLike | None] = ()) -> Path:
    """``path`` as a Path once it can be written as a new or replaced file; ``InputError`` naming
    ``what`` (the option, e.g. ``--out``) and ``path`` otherwise. ``inputs`` and ``outputs``: the
    command's other files (None entries are skipped); ``suffixes``: the lower-case suffixes it writes
    (e.g. ``(".glb", ".gltf")``), any when empty; ``libraries``: library folders the command reads or
    writes, inside which nothing else may be written."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise InputError(f"{what} {str(path)!r}: give a file name")
    if p.is_dir():
        raise InputError(f"{what} {p}: is a folder; give a file name in it")
    allowed = tuple(s.lower() for s in suffixes)
    if allowed and p.suffix.lower() not in allowed:
        raise InputError(f"{what} {p}: writes {' or '.join(allowed)} files, not {p.suffix or 'a file without suffix'}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.exists():
        raise InputError(f"{what} {p}: the folder {folder} does not exist")
    if not folder.is_dir():
        raise InputError(f"{what} {p}: {folder} is a file, not a folder")
    if not os.access(folder, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise InputError(f"{what} {p}: cannot write there (permission denied)")
    for lib in libraries:
        if lib is not None and inside(p, lib):
            raise InputError(f"{what} {p}: lies inside the library {lib}, whose files only the library "
                             "writes; choose a path outside it")
    for kind, others in (("the input", inputs), ("also another output", outputs)):
        for other in others:
            if other is not None and same_file(p, other):
                raise InputError(f"{what} {p}: is {kind} {other}; choose another name")
    return p


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` name the same file: the same existing file (links included), or, when
    either does not exist yet, the same name in the same folder once the links in the folders' paths
    are resolved (``dir/x.glb`` and ``link-to-dir/x.glb``)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return _entry(a) == _entry(b)


def _entry(path: Path) -> Path:
    """The folder entry a write to ``path`` creates or replaces: its folder with every link resolved,
    and its own name (a temporary file renamed over a link replaces the link, not its target)."""
    path = path.absolute()
    try:
        if path.name in ("", ".", ".."):
            return path.resolve()
        return path.parent.resolve() / path.name
    except (OSError, RuntimeError):  # a link loop
        return Path(os.path.abspath(path))


def inside(path: PathLike, folder: PathLike) -> bool:
    """Whether ``path`` lies in ``folder`` or below it (links resolved, the path need not exist)."""
    try:
        return Path(path).resolve().is_relative_to(Path(folder).resolve())
    except (OSError, RuntimeError):  # a link loop
        return False
