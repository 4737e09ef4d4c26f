"""Split a whole-tree HBL into library examples (VRTree Fig. 2 c, "Examples library").

One example per main branch: the main branch (index 0, no parent), the secondary branches that connect
to it (their ``parent`` set to 0) and the lobes those feed. Each example gets descriptors and tags
(``arboretum_library.descriptors``) and a ``Provenance`` naming the source file, its SHA-256, the
species and the decomposition options.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from arboretum_library.descriptors import describe, tags_for
from arboretum_library.model import HBL, Branch, Example, Level, Lobe, Provenance

from .options import DecomposeOptions


def split_structures(hbl: HBL) -> list[HBL]:
    """One HBL per MAIN branch of ``hbl``: the main at index 0, its secondary branches, their lobes."""
    feeds: dict[int, list[int]] = {}
    for j, lobe in enumerate(hbl.lobes):
        feeds.setdefault(lobe.branch, []).append(j)
    out = []
    for m in hbl.by_level(Level.MAIN):
        main = hbl.branches[m]
        branches = [Branch(main.points, main.radii, -1, -1, Level.MAIN)]
        lobes = []
        for i, b in enumerate(hbl.branches):
            if b.level != Level.SECONDARY or b.parent != m:
                continue
            branches.append(Branch(b.points, b.radii, 0, b.parent_vertex, Level.SECONDARY))
            for j in feeds.get(i, []):
                lb = hbl.lobes[j]
                lobes.append(Lobe(lb.points, lb.hull_vertices, lb.hull_faces, lb.centre, len(branches) - 1))
        out.append(HBL(main.points[0], branches, lobes))
    return out


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of the file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


SCAN_EXAMPLES_KEY = "scan_examples"
"""Provenance parameter holding how many examples the scan gave (``library build`` tells a complete scan
on resume by it; ``decompose`` a surplus left by an interrupted ``--rebuild``)."""
UP_AXIS_KEY = "up_axis"
"""Provenance parameter of ``decompose`` and ``library build``: the file's up axis as read ('z' or 'y';
missing in examples stored before session 12, which then match either). A rerun with another ``--up``
is another decomposition of the file."""


NOTES_KEY = "decompose_notes"
"""Provenance parameter of ``library build``: the scan's decomposition notes (reported again when a rerun
skips it)."""
RUN_RECORDS = (SCAN_EXAMPLES_KEY, NOTES_KEY)
"""Provenance parameters that record what a run gave, not how it was made."""
LABELS_ONLY = ("leaf_off",)
"""Decomposition options that change the reported point labels only: examples carry no labels, so runs that
differ in them make the same examples (session 15's review: ``--leaf-off`` stored every example twice)."""


def run_key(prov: Provenance, up_axis: str | None = None) -> str:
    """What two examples of one file share when one run made them: the species and every decomposition
    parameter but ``LABELS_ONLY``, with the up axis (``up_axis`` stands in for one stored without it), as
    JSON, numbers as floats (a height stored as 2 by a Python caller is the command's 2.0). ``decompose``
    stores one file with other options beside a run; ``decompose`` and ``library build`` both tell the
    runs apart by this (``split_runs``)."""
    params = {k: float(v) if isinstance(v, int | float) and not isinstance(v, bool) else v
              for k, v in prov.parameters.items() if k not in RUN_RECORDS and k not in LABELS_ONLY}
    params.setdefault(UP_AXIS_KEY, up_axis)
    return json.dumps([prov.species, params], sort_keys=True)


def same_run(a: Provenance, b: Provenance) -> bool:
    """Whether ``a`` and ``b`` (examples of one file) come from one run (``run_key``); an example stored
    without an up axis (before session 12) matches either axis, whichever side it is on."""
    up = a.parameters.get(UP_AXIS_KEY) or b.parameters.get(UP_AXIS_KEY)
    return run_key(a, up) == run_key(b, up)


def split_runs(lib, ids: list[str], want: Provenance) -> tuple[list[str], list[str]]:
    """(ids, other ids): ``ids`` (examples of one file in ``lib``) split by whether they come from the
    run of ``want`` (``same_run``)."""
    same, other = [], []
    for id_ in ids:
        (same if same_run(lib.provenance(id_), want) else other).append(id_)
    return same, other


def provenance(source: str | Path, options: DecomposeOptions, sha256: str | None = None) -> Provenance:
    """Provenance of examples decomposed from the file ``source`` with ``options``."""
    path = Path(source)
    digest = sha256 if sha256 is not None else (file_sha256(path) if path.is_file() else "")
    return Provenance(path.name, digest, options.species.lower(), options.as_dict())


def make_examples(hbl: HBL, prov: Provenance, new_id: Callable[[], str] | None = None) -> list[Example]:
    """Examples of every main branch of ``hbl`` with descriptors and tags; ids from ``new_id()``
    (default ``example-NNNN``; ``Library.add_new`` gives them library ids when it stores them)."""
    new_id = new_id or counter_ids("example")
    out = []
    for s in split_structures(hbl):
        d = describe(s)
        out.append(Example(new_id(), s, prov, d, tags_for(d)))
    return out


def counter_ids(prefix: str) -> Callable[[], str]:
    """An id source ``prefix-000``, ``prefix-001``, ... (for use without a library)."""
    state = iter(range(10**9))
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in prefix) or "example"
    return lambda: f"{safe}-{next(state):03d}"


def example_points(examples: list[Example]) -> np.ndarray:
    """All lobe points (M, 3) of ``examples`` (for checks and previews)."""
    pts = [lb.points for e in examples for lb in e.structure.lobes]
    return np.concatenate(pts) if pts else np.zeros((0, 3))
