"""Automatic recombination (VRTree 3.5): join placed examples whose main branches come near each other.

Placement ``b`` may join ``a`` when the base of ``b``'s main branch lies within ``near`` (a fraction of
``b``'s main-branch length) of ``a``'s main branch (and, if set, their shape-context similarity cost,
decompose.similarity, is at most ``max_cost``); among such ``a`` it joins the most similar one (P_opt). The link records
Algorithm 1's walk from the root: ``vertex_b`` is the first vertex of ``b``'s main branch farther than
``tau`` from ``a``'s, ``vertex_a`` the vertex of ``a`` nearest the last merged one. Each placement joins
at most one other (the most similar), and links never form a cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from arboretum_library.assembly import Assembly, MergeLink
from arboretum_library.geometry import point_polyline_distance, polyline_lengths, resample_polyline

from .world import ExampleSource, main_world


@dataclass(frozen=True)
class RecombineOptions:
    """When two placed examples merge."""

    near: float = 0.1
    """Base of b's main branch within this fraction of its length from a's main branch: they may merge."""
    tau: float = 0.025
    """Algorithm 1's merge threshold as a fraction of b's main-branch length (0.02 m at the paper's 0.8 m)."""
    max_cost: float | None = None
    """Highest shape-context assignment cost allowed (a sum of chi-square costs in [0, 1] over ``resample``
    vertices). None: no ceiling, nearness alone decides and the similarity picks P_opt among the near
    candidates, as in Algorithm 1 (the cost of two nearly straight branches is already noisy, 10-20)."""
    resample: int = 24
    """Vertices each main branch is resampled to for the similarity."""
    bins: tuple[int, int, int] = (5, 6, 4)
    """Shape-context bins (log-radius, azimuth, elevation)."""
    enabled: bool = True
    """False: never link automatically."""


def similarity(a: np.ndarray, b: np.ndarray, o: RecombineOptions = RecombineOptions()) -> float:
    """Shape-context optimal-assignment cost of two polylines (lower is more similar)."""
    from arboretum_server.decompose.similarity import similarity_costs

    ra, rb = resample_polyline(a, o.resample), resample_polyline(b, o.resample)
    return float(similarity_costs(ra[None], rb[None], o.bins)[0, 0])


def candidate(a_name: str, a: np.ndarray, b_name: str, b: np.ndarray,
              o: RecombineOptions) -> tuple[float, MergeLink] | None:
    """(cost, link a <- b) when ``b`` (N, 3) may merge into ``a`` (M, 3), else None."""
    length = polyline_lengths(b)[-1]
    if length <= 0 or point_polyline_distance(b[:1], a)[0] > o.near * length:
        return None
    cost = similarity(a, b, o)
    if o.max_cost is not None and cost > o.max_cost:
        return None
    far = point_polyline_distance(b, a) >= o.tau * length
    k = int(np.argmax(far)) if far.any() else len(b) - 1
    va = int(np.argmin(np.linalg.norm(a - b[max(k - 1, 0)], axis=1)))
    return cost, MergeLink(a_name, b_name, va, k)


def _ancestors(merges: list[MergeLink], name: str) -> set[str]:
    parent = {m.b: m.a for m in merges}
    out: set[str] = set()
    while name in parent and name not in out:
        out.add(name)
        name = parent[name]
    out.add(name)
    return out


def recombine(assembly: Assembly, source: ExampleSource, instance: str,
              o: RecombineOptions = RecombineOptions()) -> tuple[Assembly, tuple[str, ...]]:
    """Redo the merge links of ``instance`` (after it was placed or moved); returns the new assembly and
    the instances now linked to it."""
    merges = [m for m in assembly.merges if instance not in (m.a, m.b)]
    if not o.enabled:
        return replace(assembly, merges=tuple(merges)), ()
    orphans = [m.b for m in assembly.merges if m.a == instance]
    by_name = {p.instance: p for p in assembly.placements}
    mains = {n: main_world(p, source(p.example_id)) for n, p in by_name.items()}
    for b in [instance, *orphans]:
        if b not in by_name or any(m.b == b for m in merges):
            continue
        best = None
        for a in by_name:
            if a == b or b in _ancestors(merges, a):
                continue
            c = candidate(a, mains[a], b, mains[b], o)
            if c is not None and (best is None or c[0] < best[0]):
                best = c
        if best is not None:
            merges.append(best[1])
    for q in by_name:
        if q == instance or any(m.b == q for m in merges) or q in _ancestors(merges, instance):
            continue
        c = candidate(instance, mains[instance], q, mains[q], o)
        if c is not None:
            merges.append(c[1])
    linked = sorted({m.a if m.b == instance else m.b for m in merges if instance in (m.a, m.b)})
    return replace(assembly, merges=tuple(merges)), tuple(linked)
