"""Keyword search over catalog rows (VRTree section 3.4: "dense", "sparse", "straight", "curved").

A query is a list of terms (a string is split on spaces and commas; case is ignored). A term matches an
example when it equals one of its tags, its species or its id ("exact"), or occurs inside its id, source,
species or one of its tags ("substring"). Ranking, best first:

1. more terms matched (an example matching every term comes before any that misses one);
2. more exact matches among them;
3. the id, alphabetically (a stable tie-break).

Examples matching no term are left out; an empty query returns every example, by id, with score 1.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from .catalog import Entry


@dataclass(frozen=True)
class SearchHit:
    """One search result."""

    id: str
    score: float
    """Fraction of the query's terms this example matched, in (0, 1]."""
    matched: tuple[str, ...]
    """The query terms it matched, in query order."""


def parse_terms(query: str | Iterable[str]) -> list[str]:
    """Lower-case terms of ``query`` without repeats, in order (strings split on spaces and commas)."""
    parts = [query] if isinstance(query, str) else list(query)
    terms: list[str] = []
    for part in parts:
        for t in re.split(r"[\s,]+", str(part).lower()):
            if t and t not in terms:
                terms.append(t)
    return terms


def match(entry: Entry, term: str) -> int:
    """2 when ``term`` equals a tag, the species or the id; 1 when it occurs inside one; else 0."""
    words = (*entry.tags, entry.species, entry.id.lower())
    if term in words:
        return 2
    return int(any(term in w for w in (*words, entry.source.lower())))


def rank(entries: Iterable[Entry], terms: list[str], limit: int | None = None) -> list[SearchHit]:
    """Hits for ``terms`` among ``entries``, best first (see the module docstring)."""
    if not terms:
        hits = [SearchHit(e.id, 1.0, ()) for e in sorted(entries, key=lambda e: e.id)]
        return hits[:limit] if limit is not None else hits
    scored = []
    for e in entries:
        found = [(t, m) for t in terms if (m := match(e, t))]
        if found:
            exact = sum(m == 2 for _, m in found)
            scored.append((-len(found), -exact, e.id, tuple(t for t, _ in found)))
    scored.sort()
    hits = [SearchHit(id_, len(found) / len(terms), found) for _, _, id_, found in scored]
    return hits[:limit] if limit is not None else hits
