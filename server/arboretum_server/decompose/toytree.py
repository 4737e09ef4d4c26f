"""A small procedural tree with ground truth, for tests and benchmarks of the decomposition.

Not a botanical model (that is arboretum_server.synth): a trunk with a leader, ``limbs`` limbs with
``twigs`` twigs each, cylinder surfaces sampled uniformly by area, and leaf cards (ellipses) along the
twigs. Returns the points, WOOD/LEAF labels and a ``TreeTruth``; a missing sector and leaf-off mode
imitate occluded and winter scans.
"""

from __future__ import annotations

import numpy as np

from arboretum_library.model import LEAF, WOOD
from arboretum_library.truth import TreeTruth


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


class _Builder:
    def __init__(self) -> None:
        self.pos: list[np.ndarray] = [np.zeros(3)]
        self.rad: list[float] = [0.16]
        self.parent: list[int] = [-1]
        self.bid: list[int] = [0]
        self.order: list[int] = [0]
        self.nbranch = 1

    def branch(self, start: int, direction: np.ndarray, length: float, r0: float, order: int,
               bend: np.ndarray, n: int = 10, same: bool = False) -> list[int]:
        b = self.bid[start] if same else self.nbranch
        self.nbranch += 0 if same else 1
        nodes, prev, d = [], start, _unit(direction)
        for k in range(1, n + 1):
            d = _unit(d + bend / n)
            self.pos.append(self.pos[prev] + d * length / n)
            self.rad.append(max(r0 * (1 - 0.8 * k / n), 0.004))
            self.parent.append(prev)
            self.bid.append(b)
            self.order.append(order)
            prev = len(self.pos) - 1
            nodes.append(prev)
        return nodes


def toy_truth(limbs: int = 6, twigs: int = 4, seed: int = 0) -> TreeTruth:
    """The skeleton and leaves of a toy tree about 8 m tall."""
    rng = np.random.default_rng(seed)
    t = _Builder()
    trunk = t.branch(0, np.array([0, 0, 1.0]), 7.5, 0.16, 0, np.zeros(3), n=25, same=True)
    tips = []
    for i in range(limbs):
        at = trunk[int(8 + 12 * i / max(limbs - 1, 1))]
        az = 2 * np.pi * i / limbs + rng.uniform(-0.3, 0.3)
        out = np.array([np.cos(az), np.sin(az), 0.0])
        limb = t.branch(at, out + np.array([0, 0, 0.9]), rng.uniform(2.6, 3.4), 0.07, 1, 0.4 * out, n=14)
        for j in range(twigs):
            node = limb[4 + 9 * j // max(twigs, 1)]
            side = _unit(np.cross(out, [0, 0, 1.0])) * (1 if j % 2 else -1)
            tips += t.branch(node, side + 0.6 * out + [0, 0, 0.5], rng.uniform(0.7, 1.0), 0.025, 2, np.zeros(3), n=5)
        tips += limb[-5:]
    tips += trunk[-5:]
    pos = np.array(t.pos)
    idx = np.array(tips)
    lp = pos[np.repeat(idx, 6)] + rng.normal(0, 0.12, (6 * len(idx), 3))
    q = rng.normal(size=(len(lp), 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return TreeTruth(pos, np.array(t.rad), np.array(t.parent), np.array(t.bid), np.array(t.order),
                     lp, q, np.full(len(lp), 0.12), np.repeat(idx, 6).astype(np.int32), model="toy")


def _cylinders(truth: TreeTruth, n: int, rng: np.random.Generator) -> np.ndarray:
    child = np.arange(1, truth.node_count)
    a, b = truth.positions[truth.parent[child]], truth.positions[child]
    r = truth.radii[child]
    area = 2 * np.pi * r * np.linalg.norm(b - a, axis=1)
    pick = rng.choice(len(child), n, p=area / area.sum())
    axis = b[pick] - a[pick]
    u = np.cross(axis, rng.normal(size=(n, 3)))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return a[pick] + rng.uniform(0, 1, (n, 1)) * axis + r[pick, None] * u


def _leaves(truth: TreeTruth, n: int, rng: np.random.Generator) -> np.ndarray:
    from arboretum_library.geometry import quat_to_matrix

    j = rng.integers(0, truth.leaf_count, n)
    ang, rad = rng.uniform(0, 2 * np.pi, n), np.sqrt(rng.uniform(0, 1, n)) * 0.5
    local = np.stack([rad * np.cos(ang) * truth.leaf_sizes[j], rad * np.sin(ang) * truth.leaf_sizes[j] * 0.5], 1)
    rots = np.array([quat_to_matrix(q) for q in truth.leaf_wxyz])
    return truth.leaf_positions[j] + np.einsum("nij,nj->ni", rots[j][:, :, :2], local)


def toy_scan(truth: TreeTruth, n: int = 20000, leaf_fraction: float = 0.5, missing_sector: float = 0.0,
             noise: float = 0.005, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(points (n', 3), labels (n',) uint8) sampled from ``truth``; ``missing_sector`` (radians) is cut out."""
    rng = np.random.default_rng(seed)
    n_leaf = int(n * leaf_fraction) if truth.leaf_count else 0
    pts = np.concatenate([_cylinders(truth, n - n_leaf, rng), _leaves(truth, n_leaf, rng)])
    lab = np.r_[np.full(n - n_leaf, WOOD), np.full(n_leaf, LEAF)].astype(np.uint8)
    pts = pts + rng.normal(0, noise, pts.shape)
    if missing_sector > 0:
        az = np.arctan2(pts[:, 1], pts[:, 0])
        keep = (np.abs(az) > missing_sector / 2) | (pts[:, 2] < 0.5)
        pts, lab = pts[keep], lab[keep]
    return pts, lab
