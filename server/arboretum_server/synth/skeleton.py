"""From a grown graph tree to the ground-truth record: node order, branches, radii and leaves.

* Nodes are sorted by hops from the root, which is a topological order (a parent is one hop nearer).
* Branches: at each node the branch continues into the child, added in the same iteration, whose
  subtree reaches farthest (in hops; ties to the lower index); every other child starts a new branch
  of order (parent's order + 1). So each iteration's paths hang off the older tree as new branches.
* Radii: the pipe model from the tips (``arboretum_library.truth.pipe_model_radii``).
* Leaves: ``leaves_per_node`` cards on every node within ``leaf_depth`` hops of a tip on branches of
  order >= 1, pointing outwards from the twig and slightly forwards, at a random roll.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from arboretum_library.truth import TreeTruth, pipe_model_radii


def label_branches(
    parent: np.ndarray, generation: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Branch id, branch order and depth (hops to the farthest tip below) per node, each (N,).

    ``parent`` (N,) must be in topological order with the root at 0; ``generation`` (N,) is the
    iteration that added each node.
    """
    n = len(parent)
    par, gen = parent.tolist(), generation.tolist()
    dep = [0] * n
    for i in range(n - 1, 0, -1):
        p = par[i]
        if dep[i] + 1 > dep[p]:
            dep[p] = dep[i] + 1
    best, bestd = [-1] * n, [-1] * n
    for i in range(1, n):
        p = par[i]
        if gen[i] == gen[p] and dep[i] > bestd[p]:
            best[p], bestd[p] = i, dep[i]
    bid, order, nxt = [0] * n, [0] * n, 1
    for i in range(1, n):
        p = par[i]
        if best[p] == i:
            bid[i], order[i] = bid[p], order[p]
        else:
            bid[i], order[i], nxt = nxt, order[p] + 1, nxt + 1
    return np.array(bid, np.int32), np.array(order, np.int32), np.array(dep, np.int64)


def matrix_to_wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (M, 4) of rotation matrices ``R`` (M, 3, 3), w >= 0."""
    m = R.reshape(-1, 3, 3)
    tr = np.trace(m, axis1=1, axis2=2)
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    q = np.zeros((len(m), 4))
    for k in range(4):
        sel = np.argmax(cand, axis=1) == k
        r = m[sel]
        if k == 0:
            s = 2.0 * np.sqrt(1.0 + tr[sel])
            q[sel] = np.stack([0.25 * s, (r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                               (r[:, 1, 0] - r[:, 0, 1]) / s], axis=1)  # fmt: skip
            continue
        i, j, c = [(0, 1, 2), (1, 2, 0), (2, 0, 1)][k - 1]
        s = 2.0 * np.sqrt(1.0 + r[:, i, i] - r[:, j, j] - r[:, c, c])
        out = np.zeros((len(r), 4))
        out[:, 0] = (r[:, c, j] - r[:, j, c]) / s
        out[:, 1 + i] = 0.25 * s
        out[:, 1 + j] = (r[:, j, i] + r[:, i, j]) / s
        out[:, 1 + c] = (r[:, c, i] + r[:, i, c]) / s
        q[sel] = out
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0, -q, q)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def place_leaves(
    pos: np.ndarray, parent: np.ndarray, radii: np.ndarray, hosts: np.ndarray, per_node: int,
    size: float, rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Leaf centres (L, 3), wxyz (L, 4), sizes (L,) and host nodes (L,) for ``per_node`` per host."""
    host = np.repeat(hosts, per_node)
    if len(host) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0), np.zeros(0, np.int32)
    t = _unit(pos[host] - pos[np.maximum(parent[host], 0)])
    a = rng.normal(size=(len(host), 3))
    o = _unit(a - (a * t).sum(axis=1, keepdims=True) * t)
    x = _unit(o + 0.5 * t)
    y = _unit(np.cross(t, x))
    z = np.cross(x, y)
    sizes = size * rng.uniform(0.8, 1.2, len(host))
    centres = pos[host] + x * (0.5 * sizes + radii[host])[:, None]
    wxyz = matrix_to_wxyz(np.stack([x, y, z], axis=2))
    return centres, wxyz, sizes, host.astype(np.int32)


def skeleton_truth(
    points: np.ndarray, st: Any, opts: Any, rng: np.random.Generator, **prov: Any
) -> TreeTruth:
    """The ``TreeTruth`` of the tree ``st`` (a ``guiding.TreeState``) grown over graph ``points``.

    ``prov`` gives model, species, seed and params (the provenance).
    """
    nodes = np.flatnonzero(st.in_tree)
    order = nodes[np.argsort(st.root_hops[nodes], kind="stable")]
    remap = np.full(len(points), -1)
    remap[order] = np.arange(len(order))
    old_parent = st.parent[order]
    parent = np.where(old_parent >= 0, remap[np.maximum(old_parent, 0)], -1)
    pos = points[order]
    bid, border, depth = label_branches(parent, st.generation[order])
    radii = pipe_model_radii(parent, opts.tip_radius, opts.pipe_exponent)
    hosts = np.flatnonzero((depth <= opts.leaf_depth) & (border >= min(1, int(border.max()))))
    leaves = place_leaves(pos, parent, radii, hosts, opts.leaves_per_node, opts.leaf_size, rng)
    return TreeTruth(
        positions=pos, radii=radii, parent=parent, branch_id=bid, branch_order=border,
        leaf_positions=leaves[0], leaf_wxyz=leaves[1], leaf_sizes=leaves[2], leaf_node=leaves[3],
        model=prov["model"], species=prov["species"], seed=prov["seed"], parameters=prov["params"],
    )  # fmt: skip
