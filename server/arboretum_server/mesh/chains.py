"""Split a tree graph into chains (one tube each): a chain follows its thickest child at every fork."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_server.grow.radii import depths


@dataclass(frozen=True, eq=False)
class Chains:
    """Chains of a tree graph, concatenated. Chain c's vertices are ``nodes[starts[c]:starts[c+1]]``.

    A chain that forks off another starts with the fork node of its parent chain, so its tube begins
    on the parent's axis (a joint hidden inside the parent tube).
    """

    nodes: np.ndarray
    """(M,) int64: graph node of each chain vertex."""
    starts: np.ndarray
    """(C + 1,) int64: CSR offsets of the chains into ``nodes``."""
    chain: np.ndarray
    """(M,) int64: chain of each chain vertex."""
    radius_node: np.ndarray
    """(M,) int64: node whose radius the vertex takes (the fork vertex takes the chain's first node)."""


def split_chains(parents: np.ndarray, radii: np.ndarray, min_nodes: int = 1) -> Chains:
    """Chains of the graph ``parents`` (N,) by thickest-child continuation; ``radii`` (N,) decide."""
    parents = np.asarray(parents, np.int64)
    n = len(parents)
    idx = np.arange(n)
    kids = np.flatnonzero(parents >= 0)
    order = kids[np.lexsort((kids, -radii[kids], parents[kids]))]
    first = np.r_[True, parents[order][1:] != parents[order][:-1]] if len(order) else np.zeros(0, bool)
    is_start = np.ones(n, bool)
    is_start[order[first]] = False
    head = np.where(is_start, idx, parents)
    while True:
        nxt = np.where(is_start[head], head, head[head])
        if np.array_equal(nxt, head):
            break
        head = nxt
    depth = depths(parents)
    pos = depth - depth[head]
    heads = np.flatnonzero(is_start)
    chain_of_head = np.full(n, -1, np.int64)
    chain_of_head[heads] = np.arange(len(heads))
    chain = chain_of_head[head]
    fork = parents[heads]
    has_fork = fork >= 0
    # chain vertices: the fork (position -1) then the chain's own nodes
    all_chain = np.r_[chain, np.flatnonzero(has_fork)]
    all_pos = np.r_[pos, np.full(int(has_fork.sum()), -1)]
    all_node = np.r_[idx, fork[has_fork]]
    all_rnode = np.r_[idx, heads[has_fork]]
    o = np.lexsort((all_pos, all_chain))
    counts = np.bincount(all_chain, minlength=len(heads))
    keep_chain = counts >= max(min_nodes, 2)
    keep = keep_chain[all_chain[o]]
    o = o[keep]
    new_id = np.cumsum(keep_chain) - 1
    counts = counts[keep_chain]
    return Chains(all_node[o], np.r_[0, np.cumsum(counts)].astype(np.int64), new_id[all_chain[o]],
                  all_rnode[o])
