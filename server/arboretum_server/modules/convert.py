"""Convert a grown tree into K module types placed many times (for instanced export).

1. Cut: the tree's chains (thickest-child continuation, ``mesh.chains.split_chains``) are cut into pieces
   of ``piece_edges`` edges; a piece starts at its first node (on a fork, the parent chain's node), so
   the pieces partition the skeleton's edges. A short remainder is joined to the piece before it.
2. Describe: each piece is resampled to ``samples`` points by arc length and put in a canonical frame
   (base at the origin, chord along +Z, the mean bend along +X), divided by its arc length; with its base
   and tip radii over arc length this is a rotation- and scale-normalised signature.
3. Cluster: k-means (``decompose.clusters``, the best of ``INITS`` seeded runs) into K types; each type's
   representative is the member nearest its centroid (a medoid), whose polyline, at its own size, is the
   module's skeleton; the module mesh is a tube along it (``mesh.tubes.sweep``).
4. Fit: every piece gets the rotation and uniform scale that best map its type's skeleton onto its own
   resampled points with the bases pinned together (orthogonal Procrustes with scale, Umeyama's SVD with
   the reflection guard), so consecutive pieces stay joined.
5. Fidelity: symmetric Chamfer distance between dense samples of the original skeleton and of the placed
   module skeletons, as a fraction of the tree's height. Leaves are not converted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.export.parts import MeshPart
from arboretum_server.decompose.clusters import kmeans
from arboretum_server.grow.skeleton import GrownTree
from arboretum_server.mesh.chains import split_chains
from arboretum_server.mesh.tubes import sweep


@dataclass(frozen=True)
class ConvertOptions:
    types: int = 16
    """K, number of module types (clusters)."""
    piece_edges: int = 6
    """Skeleton edges per piece (a chain segment)."""
    samples: int = 8
    """Points each piece is resampled to for its signature and the fit."""
    radius_weight: float = 4.0
    """Weight of the radius-over-length features against the shape coordinates in the signature."""
    sides: int = 6
    """Tube sides of the module meshes."""
    rings: int = 8
    """Tube rings along each module mesh (its skeleton resampled to this many points)."""
    dense: int = 16
    """Samples per piece for the Chamfer distance."""


@dataclass(frozen=True, eq=False)
class ConvertedTree:
    """A grown tree as placed module instances."""

    meshes: tuple[MeshPart, ...]
    """One tube mesh per module type, module frame (base at the origin, chord +Z, metres)."""
    skeletons: np.ndarray
    """(K, S, 3) float64 each type's skeleton polyline, module frame."""
    module: np.ndarray
    """(P,) int64 type of each piece."""
    T_world_module: np.ndarray
    """(P, 4, 4) float64 world (Z up) from module frame: rotation, uniform scale, translation."""
    parent: np.ndarray
    """(P,) int64 the piece holding each piece's first node, -1 for the root piece."""
    height: float
    """Height of the tree's skeleton (z range, metres)."""
    chamfer: float
    """Symmetric Chamfer distance original vs reconstructed skeleton (metres)."""

    @property
    def chamfer_fraction(self) -> float:
        return self.chamfer / max(self.height, 1e-12)


def cut_pieces(parents: np.ndarray, radii: np.ndarray, piece_edges: int) -> list[np.ndarray]:
    """Node index polylines (each >= 2 nodes) partitioning the edges of the tree ``parents`` (N,)."""
    ch = split_chains(parents, radii)
    pieces: list[np.ndarray] = []
    for c in range(len(ch.starts) - 1):
        nodes = ch.nodes[ch.starts[c]:ch.starts[c + 1]]
        edges = len(nodes) - 1
        if edges < 1:
            continue
        cuts = list(range(0, edges, piece_edges)) + [edges]
        if len(cuts) > 2 and cuts[-1] - cuts[-2] < piece_edges / 2:
            del cuts[-2]
        pieces += [nodes[a:b + 1] for a, b in zip(cuts[:-1], cuts[1:])]
    return pieces


def resample_pieces(pieces: list[np.ndarray], positions: np.ndarray, values: np.ndarray,
                    n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each piece's points (P, n, 3) and per-node ``values`` (P, n) at ``n`` even arc lengths; lengths (P,).

    Pieces are padded with their last node (zero-length segments), so all are resampled at once.
    """
    sizes = np.array([len(p) for p in pieces])
    width = int(sizes.max())
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    j = np.minimum(np.arange(width)[None], sizes[:, None] - 1)
    idx = np.concatenate(pieces)[start[:, None] + j]
    pts, val = positions[idx], values[idx]
    seg = np.linalg.norm(np.diff(pts, axis=1), axis=2)
    arc = np.concatenate([np.zeros((len(idx), 1)), np.cumsum(seg, axis=1)], axis=1)
    u = arc[:, -1:] * np.linspace(0.0, 1.0, n)[None]
    k = np.clip((arc[:, None, :] <= u[:, :, None]).sum(axis=2) - 1, 0, width - 2)
    a0 = np.take_along_axis(arc, k, axis=1)
    a1 = np.take_along_axis(arc, k + 1, axis=1)
    f = np.where(a1 > a0, (u - a0) / np.where(a1 > a0, a1 - a0, 1.0), 0.0)
    p = _take(pts, k) * (1 - f[..., None]) + _take(pts, k + 1) * f[..., None]
    v = _take(val, k) * (1 - f) + _take(val, k + 1) * f
    return p, v, arc[:, -1]


def _take(x: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Rows ``x[p, j[p, s]]`` of (P, M[, 3]) ``x`` for (P, S) indices ``j``."""
    return np.take_along_axis(x, j[..., None] if x.ndim == 3 else j, axis=1)


def canonical_frames(P: np.ndarray) -> np.ndarray:
    """(P, 3, 3) rows x, y, z of each piece's frame: z = chord, x = mean perpendicular bend, y = z × x."""
    rel = P - P[:, :1]
    chord = rel[:, -1]
    n = np.linalg.norm(chord, axis=1, keepdims=True)
    z = np.where(n > 1e-12, chord / np.maximum(n, 1e-12), [0.0, 0.0, 1.0])
    bend = rel.mean(axis=1)
    bend -= (bend * z).sum(1, keepdims=True) * z
    fallback = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    fallback -= (fallback * z).sum(1, keepdims=True) * z
    bn = np.linalg.norm(bend, axis=1, keepdims=True)
    x = np.where(bn > 1e-9 * np.maximum(n, 1e-12), bend, fallback)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], axis=1)


def signatures(P: np.ndarray, r: np.ndarray, length: np.ndarray, radius_weight: float) -> np.ndarray:
    """(P, 3 S + 2) rotation/scale-normalised signatures of resampled pieces ``P`` (P, S, 3), radii (P, S)."""
    F = canonical_frames(P)
    local = np.einsum("pij,psj->psi", F, P - P[:, :1]) / np.maximum(length, 1e-12)[:, None, None]
    rad = radius_weight * np.stack([r[:, 0], r[:, -1]], axis=1) / np.maximum(length, 1e-12)[:, None]
    return np.concatenate([local.reshape(len(P), -1), rad], axis=1)


def fit_pinned(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (P, 3, 3) and scales (P,) minimising |s R src + dst[0] - dst| with src[0] at the origin.

    ``src``, ``dst``: (P, S, 3). Orthogonal Procrustes about the pinned base (Umeyama's SVD, det guard).
    """
    a = src - src[:, :1]
    b = dst - dst[:, :1]
    cov = np.einsum("psi,psj->pij", b, a)
    U, D, Vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    d[d == 0] = 1.0
    S = np.ones((len(a), 3))
    S[:, 2] = d
    R = np.einsum("pij,pj,pjk->pik", U, S, Vt)
    var = (a**2).sum(axis=(1, 2))
    s = (D * S).sum(axis=1) / np.maximum(var, 1e-300)
    return R, np.maximum(s, 1e-9)


INITS = 4
"""k-means runs per conversion, each from its own k-means++ start; the one with the least inertia is kept."""


def _cluster(sig: np.ndarray, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Labels (P,) and medoid piece per type (K,), types renumbered by first appearance.

    The best of ``INITS`` k-means runs (``decompose.clusters``, one thread: the same types on any machine),
    seeded by one draw from ``rng``. Until session 31 scikit-learn's ``KMeans(n_init=4)``, whose import cost
    ``arboretum modules`` 0.9-1.3 s here."""
    k = min(k, len(np.unique(sig.round(12), axis=0)))
    runs = np.random.default_rng(int(rng.integers(0, 2**31 - 1)))
    best = None
    for _ in range(INITS):
        labels, centres = kmeans(sig, k, runs)
        inertia = float(((sig - centres[labels]) ** 2).sum())
        if best is None or inertia < best[0]:
            best = (inertia, labels.astype(np.int64), centres)
    _, labels, centres = best
    _, first = np.unique(labels, return_index=True)
    order = labels[np.sort(first)]
    k = len(order)
    remap = np.full(len(centres), -1, np.int64)
    remap[order] = np.arange(k)
    labels = remap[labels]
    centres = centres[order]
    d = np.linalg.norm(sig - centres[labels], axis=1)
    medoid = np.array([np.flatnonzero(labels == t)[np.argmin(d[labels == t])] for t in range(k)])
    return labels, medoid


def _tube(points: np.ndarray, radii: np.ndarray, sides: int, name: str) -> MeshPart:
    parents = np.arange(len(points)) - 1
    tubes = sweep(points, radii, split_chains(parents, radii), sides)
    return MeshPart(name, tubes.positions, tubes.faces, tubes.normals, None, 0)


def _chamfer(a: np.ndarray, b: np.ndarray) -> float:
    from scipy.spatial import cKDTree

    return 0.5 * float(cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def convert_tree(tree: GrownTree, options: ConvertOptions, rng: np.random.Generator) -> ConvertedTree:
    """Cut ``tree`` into pieces, cluster them into ``options.types`` module types, fit every piece."""
    o = options
    if o.types < 1 or o.piece_edges < 1 or o.samples < 3:
        raise InputError("convert: need types >= 1, piece_edges >= 1 and samples >= 3")
    pieces = cut_pieces(tree.parents, tree.radii, o.piece_edges)
    if not pieces:
        raise InputError("convert: the tree has no branches (a single node)")
    P, r, length = resample_pieces(pieces, tree.positions, tree.radii, o.samples)
    labels, medoid = _cluster(signatures(P, r, length, o.radius_weight), o.types, rng)
    F = canonical_frames(P[medoid])
    skel = np.einsum("kij,ksj->ksi", F, P[medoid] - P[medoid][:, :1])
    S = o.samples
    flat_skel = skel.reshape(-1, 3)
    per_type = [np.arange(t * S, (t + 1) * S) for t in range(len(skel))]
    ring_pts, ring_r, _ = resample_pieces(per_type, flat_skel, r[medoid].reshape(-1), max(o.rings, 2))
    meshes = tuple(_tube(ring_pts[t], ring_r[t], o.sides, f"module_{t:02d}") for t in range(len(skel)))
    R, s = fit_pinned(skel[labels], P)
    T = np.tile(np.eye(4), (len(P), 1, 1))
    T[:, :3, :3] = R * s[:, None, None]
    T[:, :3, 3] = P[:, 0]
    dense_skel = resample_pieces(per_type, flat_skel, np.zeros(len(flat_skel)), o.dense)[0]
    rec = np.einsum("pij,psj->psi", T[:, :3, :3], dense_skel[labels]) + T[:, None, :3, 3]
    orig = resample_pieces(pieces, tree.positions, tree.radii, o.dense)[0]
    height = float(np.ptp(tree.positions[:, 2]))
    chamfer = _chamfer(orig.reshape(-1, 3), rec.reshape(-1, 3))
    return ConvertedTree(meshes, skel, labels, T, _piece_parents(pieces, len(tree.positions)), height, chamfer)


def _piece_parents(pieces: list[np.ndarray], n_nodes: int) -> np.ndarray:
    """(P,) the piece owning each piece's first node (as a non-first node), -1 if none."""
    owner = np.full(n_nodes, -1, np.int64)
    for i, p in enumerate(pieces):
        owner[p[1:]] = i
    return np.array([owner[p[0]] for p in pieces], np.int64)
