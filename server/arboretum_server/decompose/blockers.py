"""Hulls known to block a lobe's candidate branches during one ``secondary.make_lobes`` call (session 25).

The repairs of ``clear`` and ``tunnel`` test many of the same segments again and again: from the main
branches' vertices to a lobe's centre or to its own points. ``secondary._unwrapped_fallback`` tests a lobe's
straight and bent routes again after carving one or two other lobes, ``tunnel.behind`` once more against the
kept lobes, and ``tunnel.moved_centre`` tries the lobe's own points that ``bent_fallback`` tried as waypoints;
most stay blocked by a lobe that did not change. A ``Blockers`` table remembers, per segment end and main
vertex, one hull that held a sample of that segment; while that very hull (the same vertex and face arrays,
tested with its own box) is among the lobes tested, the segment is blocked without a test. Identities are
checked at every use, so an entry can only be missing, never wrong; the tables go at the start and end of
each ``make_lobes`` call (``forget_blockers``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .memo import ArrayMemo
from .state import LobeState


def own_rows(box: tuple[np.ndarray, np.ndarray], own: tuple[np.ndarray, np.ndarray], j: int) -> np.ndarray:
    """(L,) bool: the lobes whose row of ``box`` is their hull's own box (``own``: ``boxes``), ``j`` left out."""
    if box[0] is own[0] and box[1] is own[1]:
        rows = np.ones(len(own[0]), bool)
    else:
        rows = (np.asarray(box[0]) == own[0]).all(axis=1) & (np.asarray(box[1]) == own[1]).all(axis=1)
    rows[j] = False
    return rows


class Pairs(NamedTuple):
    """Segments from main-branch vertices to a set of ends, for the known blockers of ``Blockers``."""

    verts: np.ndarray
    """(V, 3) the main vertices (``main_vertices``) the segments start from."""
    starts: np.ndarray
    """(S,) each segment's start, an index into ``verts``."""
    ends: np.ndarray
    """(E, 3) the segments' ends."""
    end_of: np.ndarray
    """(S,) each segment's end, an index into ``ends``."""
    members: np.ndarray | None = None
    """(E,) each end's position among the lobe's members when the ends are its own points (``pts``), else None."""
    pts: np.ndarray | None = None
    """The points the lobe's members index (with ``members``)."""


BLOCKER_ENDS_KEPT = 4096
"""Segment ends a ``Blockers`` keeps at most (it starts again empty past this)."""


class Blockers:
    """One lobe's known blockers during one ``secondary.make_lobes`` call: per segment end and main vertex,
    a hull known to hold one of the samples (``clear.blocked``'s, at ``step``) of the segment from that vertex
    to that end (-1: none known). An end is named by its position among the lobe's members when it is one of
    its points, else by its coordinates' bytes."""

    def __init__(self, verts: np.ndarray, step: float) -> None:
        self.verts, self.step = verts, step
        """The main vertices the segments start from (their indices key the table) and the sample spacing."""
        self.hulls: list[tuple[np.ndarray, np.ndarray]] = []
        """The hulls named, held (vertex and face arrays): their ids stay theirs."""
        self.ids: dict[tuple[int, int], int] = {}
        self.table = np.full((16, len(verts)), -1, np.int32)
        """(rows, V): the hull (index into ``hulls``) blocking each end's (row's) segment from each vertex."""
        self.used = 0
        self.by_point: dict[bytes, int] = {}
        """Row of each end named by its coordinates."""
        self.pts: np.ndarray | None = None
        self.by_member = np.zeros(0, np.int32)
        """Row of each of the lobe's members (-1: none), for ends among them (indexing ``pts``)."""

    @staticmethod
    def of(lb: LobeState, verts: np.ndarray, step: float) -> Blockers:
        """The blockers kept for lobe ``lb`` (by its members array) with segments from ``verts`` every ``step``."""
        hit = _BLOCKERS[0].get(lb.members)
        if hit is not None and hit.verts is verts and hit.step == step and hit.used <= BLOCKER_ENDS_KEPT:
            return hit
        return _BLOCKERS[0].put(lb.members, Blockers(verts, step))

    def _rows(self, pairs: Pairs, n_members: int, add: np.ndarray | None = None) -> np.ndarray:
        """(E,) the row of each end of ``pairs`` (-1: none); ends flagged in ``add`` get a new row if they have none."""
        if pairs.members is not None:
            if self.pts is not pairs.pts or len(self.by_member) != n_members:
                self.pts, self.by_member = pairs.pts, np.full(n_members, -1, np.int32)
            rows = self.by_member[pairs.members]
            new = np.flatnonzero((rows < 0) & add) if add is not None else ()
            if len(new):
                rows[new] = self._grow(len(new))
                self.by_member[pairs.members[new]] = rows[new]
            return rows
        keys = [e.tobytes() for e in np.ascontiguousarray(pairs.ends, np.float64)]
        rows = np.array([self.by_point.get(k, -1) for k in keys], np.int64)
        for e in (np.flatnonzero((rows < 0) & add) if add is not None else ()):
            rows[e] = self.by_point.setdefault(keys[e], int(self._grow(1)[0]))
        return rows

    def _grow(self, n: int) -> np.ndarray:
        """``n`` new rows (-1 throughout)."""
        if self.used + n > len(self.table):
            more = np.full((max(len(self.table), n), self.table.shape[1]), -1, np.int32)
            self.table = np.concatenate([self.table, more])
        self.used += n
        return np.arange(self.used - n, self.used)

    def prior(self, lobes: list[LobeState], j: int, held: np.ndarray, pairs: Pairs,
              index: dict[int, int]) -> np.ndarray | None:
        """(S,) int64 for ``hullpack.segments_blocked``: the index among ``lobes`` of a hull known to block each
        segment of ``pairs`` whose box row is its own (``held``), -1 for none; None when none is known."""
        rows = self._rows(pairs, len(lobes[j].members))[pairs.end_of]
        known = np.where(rows >= 0, self.table[np.maximum(rows, 0), pairs.starts], -1)
        if not (known >= 0).any():
            return None
        now = np.full(len(self.hulls), -1, np.int64)  # hull -> its index among lobes, -1 if absent or not held
        for r in np.unique(known[known >= 0]).tolist():
            verts, faces = self.hulls[r]
            k = index.get(id(verts))
            if k is not None and lobes[k].hull_vertices is verts and lobes[k].hull_faces is faces and held[k]:
                now[r] = k
        return np.where(known >= 0, now[np.maximum(known, 0)], -1)

    def keep(self, lobes: list[LobeState], j: int, held: np.ndarray, pairs: Pairs, by: np.ndarray) -> None:
        """Keep the hulls ``by`` (index among ``lobes``, -1 none) found blocking the segments of ``pairs``,
        those whose box row was their own (``held``)."""
        ok = by >= 0
        ok[ok] = held[by[ok]]
        if not ok.any():
            return
        name = np.full(len(lobes), -1, np.int32)
        for k in np.unique(by[ok]).tolist():
            key = (id(lobes[k].hull_vertices), id(lobes[k].hull_faces))
            if key not in self.ids:
                self.ids[key] = len(self.hulls)
                self.hulls.append((lobes[k].hull_vertices, lobes[k].hull_faces))
            name[k] = self.ids[key]
        add = np.zeros(len(pairs.ends), bool)
        add[pairs.end_of[ok]] = True
        rows = self._rows(pairs, len(lobes[j].members), add)
        self.table[rows[pairs.end_of[ok]], pairs.starts[ok]] = name[by[ok]]


_BLOCKERS = [ArrayMemo()]
"""``Blockers`` of each lobe by its members array, during one ``secondary.make_lobes`` call."""


def forget_blockers() -> None:
    """Drop every lobe's known blockers (``secondary.make_lobes`` does at its start and end: they hold a row per
    end tried, so they are kept for one call only)."""
    _BLOCKERS[0] = ArrayMemo()
