"""What a build does with each scan, decided from the library before any worker starts.

A scan (by the SHA-256 of its bytes) with examples in the library is *skipped*, and its record shows what
is stored: the stored species and notes, plus a note when

- some of its examples are gone (``scan_examples`` in the provenance says how many it gave). A scan's
  examples are stored all or none (``Library.add_new``, one group journal that a crash rolls back), so a
  shortfall usually means examples were deleted afterwards with ``arboretum library delete``: the build
  keeps that pruning. A folder lost whole in a power loss (its rename never reached the disk) looks the
  same: ``--rebuild`` restores it. Only when the library's ``quarantine/`` holds a damaged example of
  the scan (a folder without a catalog row found broken when the library was opened) is the scan done
  again (``redone``);
- the stored examples were made with other options than this run's (species, points, height, seed);
- the library also holds examples of another file of the same name with other contents (an earlier
  version of an edited scan, or a namesake from another folder: the library keeps only file names, so
  they are reported, never deleted).

A scan is also done again when one of its examples has files of another size than its catalog row
records (``_torn``: an unsynced build's folder torn by a power loss while its row survived, typically an
emptied arrays.npz); two ``stat`` calls an example. Files torn at their right size are not noticed
until read (``Library.get`` names the example): ``arboretum library delete`` it, then build the scan
again with ``--rebuild`` (without it, the scan short of an example is kept as pruned).

With ``rebuild`` (or a damaged scan) the scan is decomposed again with this run's options and, in
one hold of the library's write lock (``build._store``), its new examples are stored first, all or none
under fresh ids (the old ones still exist, so ``Library.add_new`` numbers the new ones after them: a
saved session naming an old id never silently shows a new example), and only then are its old examples deleted. A
scan whose decomposition fails, or whose new examples cannot be stored (disk full, another writer
holding the lock, Ctrl-C), keeps its old examples untouched. Stopped while the old ones are being
deleted (Ctrl-C, a crash), the library holds the new examples and some old ones: the next build
notes more examples than ``scan_examples``; ``--rebuild`` replaces them all.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from arboretum_library.folders import ARRAYS, META, safe_prefix

from .tasks import NOTES_KEY, SCAN_EXAMPLES_KEY

COMPARED = ("points", "height", "seed")
"""Decomposition options a build sets besides the species; a stored scan made with others gets a note."""


def scan_stem(path: str) -> str:
    """The id prefix of a scan's examples: its file stem made safe exactly as ``Library.add_new`` makes
    it (``folders.safe_prefix``: ``apple tree (2).xyz`` -> ``apple-tree--2``)."""
    return safe_prefix(Path(path).stem)


def plan(lib, records: list, options: Any = None) -> list:
    """Hash every record's scan, set the status of those not to run (failed, duplicate, skipped) with
    their notes, and mark those whose stored examples are to be replaced (``record.replace``). Returns the
    records to decompose. ``options``: a ``BuildOptions`` (None: compare nothing, rebuild nothing)."""
    from arboretum_server.decompose.examples import file_sha256

    seen: set[str] = set()
    todo = []
    entries = lib.entries()
    sizes = {e.id: e.size_bytes for e in entries}
    for r in records:
        try:
            r.sha256 = file_sha256(r.path)
        except OSError as exc:
            r.status, r.error = "failed", f"cannot read the file ({exc.strerror or exc})"
            continue
        if r.sha256 in seen:
            r.status = "duplicate"
            continue
        seen.add(r.sha256)
        ids = lib.find_source(r.sha256)
        if ids and (getattr(options, "rebuild", False) or _torn(lib, r, ids, sizes) or _damaged(lib, r, ids)):
            r.replace = list(ids)  # counted in BuildResult.redone once stored (build_library)
        elif ids:
            _skip(lib, r, ids, options)
            continue
        todo.append(r)
    _namesakes(entries, records, seen)
    return todo


def _one_run(lib, ids: list[str]) -> list[str]:
    """The ids among ``ids`` (examples of one file) made in the run of ``ids[0]`` (``examples.run_key``):
    ``decompose`` stores the same file with other options beside them (session 12)."""
    from arboretum_server.decompose.examples import split_runs

    return split_runs(lib, ids, lib.provenance(ids[0]))[0]


def _skip(lib, r, ids: list[str], options: Any) -> None:
    prov = lib.provenance(ids[0])
    params = prov.parameters
    r.status, r.examples = "skipped", list(ids)
    r.notes = list(params.get(NOTES_KEY, []))
    want = params.get(SCAN_EXAMPLES_KEY)
    run = _one_run(lib, ids) if want is not None else ids
    if want is not None and len(run) < int(want):
        r.notes.append(f"{int(want) - len(run)} of its {int(want)} examples are no longer in the library "
                       "(deleted since it was built, or lost in a power loss): kept so; --rebuild makes "
                       "them all again")
    elif want is not None and len(run) > int(want):
        r.notes.append(f"the library holds {len(run)} examples of it, not the {int(want)} it gives: a "
                       "--rebuild stopped while deleting the old ones; --rebuild again replaces them all")
    differ = [("species", prov.species, r.species)] if options is not None and prov.species != r.species else []
    differ += [(k, params.get(k), getattr(options, k)) for k in COMPARED
               if options is not None and k in params and params.get(k) != getattr(options, k)]
    r.species = prov.species  # what is stored, not what this run would have made
    if differ:
        was = ", ".join(f"--{k} {_arg(old)}" for k, old, _ in differ)
        now = ", ".join(f"--{k} {_arg(new)}" for k, _, new in differ)
        r.notes.append(f"its {len(ids)} examples were made with {was}, not this run's {now}: left as they "
                       "are; --rebuild decomposes it again with this run's options (or delete them: "
                       "arboretum library delete)")


def _arg(value: Any) -> Any:
    """An option's value as the command line gives it: a height of None (the scan's units) is --height 0."""
    return 0 if value is None else value


def _damaged(lib, r, ids: list[str]) -> bool:
    """Whether the scan lost examples to ``quarantine/`` (damaged folders found when the library was
    opened after a crash): a quarantined folder of this scan (by its provenance, or by its id's prefix
    when its meta.json is unreadable) whose id is no longer in the library, moved there after the scan's
    examples were stored (an older one was handled by an earlier build, which stored them again)."""
    from arboretum_library.folders import quarantined, read_provenance

    held = quarantined(lib.root)
    if not held:  # the common case: no meta.json read at all (_skip reads it once)
        return False
    want = lib.provenance(ids[0]).parameters.get(SCAN_EXAMPLES_KEY)
    if want is None or len(ids) >= int(want):
        return False
    stem = scan_stem(r.path)
    stored = max((_ctime(Path(lib.root) / "examples" / i) for i in ids), default=0.0)
    for id_, folder in held:
        if id_ in ids or id_ in lib or not id_.startswith(f"{stem}-") or _ctime(folder) < stored:
            continue  # not this scan's, or quarantined before its examples were (re)stored
        try:
            sha = read_provenance(folder).source_sha256
        except Exception:  # torn beyond reading: its name is all there is
            return True
        if sha == r.sha256:
            return True
    return False


def _ctime(path: Path) -> float:
    """When ``path`` was last renamed or changed (0 when it is gone)."""
    try:
        return path.stat().st_ctime
    except OSError:
        return 0.0


def _torn(lib, r, ids: list[str], sizes: dict[str, int]) -> bool:
    """Whether an example of the scan has files of another size than its catalog row records (the size
    of meta.json plus arrays.npz when stored): a folder torn by a power loss after an unsynced build, its
    row intact (the files' data had not reached the disk: typically left empty). Two ``stat`` calls an
    example; contents torn at the right size are not seen here (``Library.get`` names them)."""
    root = Path(lib.root) / "examples"
    for id_ in ids:
        try:
            size = sum((root / id_ / name).stat().st_size for name in (META, ARRAYS))
        except OSError:
            size = -1
        if size != sizes.get(id_, size):
            r.notes.append(f"its example {id_} is damaged (its files are not the size the library "
                           "recorded: cut short by a power loss?): the scan is done again")
            return True
    return False


def _namesakes(entries: list, records: list, given: set[str]) -> None:
    """Note, on every record, examples in the library from a file of the same name whose contents are
    not among the scans given (an earlier version of an edited scan: stale; or a namesake elsewhere)."""
    by_name: dict[str, dict[str, list[str]]] = {}
    for e in entries:
        by_name.setdefault(e.source, {}).setdefault(e.source_sha256, []).append(e.id)
    for r in records:
        other = {sha: ids for sha, ids in by_name.get(Path(r.path).name, {}).items() if sha not in given}
        if not other or not r.sha256:
            continue
        ids = sorted(i for group in other.values() for i in group)
        shown = " ".join(ids[:4]) + (" ..." if len(ids) > 4 else "")
        r.notes.append(f"the library also holds {len(ids)} examples of a file named {Path(r.path).name} "
                       f"with other contents ({shown}): an earlier version of this scan? They are kept; "
                       "if stale, delete them: arboretum library delete LIB ID")
