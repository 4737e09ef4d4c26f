"""Module skeleton curves from a branch mesh (Takikawa et al. 2025, Appendix A).

Geodesic distance from the base over the mesh edges; isolines of that field at evenly spaced values,
found face by face and grouped into islands with a disjoint set; island centroids joined level to
level into splines. Where an island splits (a fork) the spline ends and each new island starts a child
spline (largest first, the paper's "parent" continuation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from arboretum_library.errors import InputError


@dataclass(frozen=True)
class ModuleSkeleton:
    points: np.ndarray
    """(P, 3) float64 curve points, module frame (Z up, metres)."""
    radius: np.ndarray
    """(P,) float64 branch radius at each point."""
    tangent: np.ndarray
    """(P, 3) float64 unit tangent, pointing away from the base."""
    spline: np.ndarray
    """(P,) int32 index of the spline each point belongs to; points of a spline are consecutive."""
    spline_parent: np.ndarray
    """(S,) int32 parent spline, -1 for the root spline."""
    base: np.ndarray
    """(3,) float64 base point (centre of the lowest isoline)."""
    base_direction: np.ndarray
    """(3,) float64 unit direction of the skeleton at the base."""
    tips: np.ndarray
    """(T,) int32 indices into ``points`` of the spline ends that have no child spline."""

    @property
    def base_radius(self) -> float:
        return float(self.radius[0])


def _edge_graph(vertices: np.ndarray, faces: np.ndarray) -> coo_matrix:
    """Sparse symmetric graph of mesh edges weighted by length, components bridged by nearest pairs."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = len(vertices)
    for _ in range(n):
        w = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
        g = coo_matrix((np.maximum(w, 1e-12), (e[:, 0], e[:, 1])), shape=(n, n))
        ncomp, label = connected_components(g, directed=False)
        if ncomp == 1:
            return g
        inside = np.flatnonzero(label == label[0])
        outside = np.flatnonzero(label != label[0])
        d, j = cKDTree(vertices[outside]).query(vertices[inside])
        k = int(np.argmin(d))
        e = np.concatenate([e, [[inside[k], outside[j[k]]]]])
    raise InputError("module mesh: could not connect its parts")


def _isoline_segments(vertices, faces, g, level):
    """The isoline g == level face by face: segment ends (S, 2, 3) and the mesh-edge keys of the ends
    (S, 2) int64 (two segments sharing a key meet there)."""
    gf = g[faces]
    hit = (gf.min(axis=1) < level) & (gf.max(axis=1) > level)
    f = faces[hit]
    ends = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        ga, gb = g[f[:, a]], g[f[:, b]]
        cross = (ga - level) * (gb - level) < 0
        t = np.where(cross, (level - ga) / np.where(cross, gb - ga, 1.0), 0.0)
        p = vertices[f[:, a]] + t[:, None] * (vertices[f[:, b]] - vertices[f[:, a]])
        key = np.minimum(f[:, a], f[:, b]).astype(np.int64) * len(vertices) + np.maximum(
            f[:, a], f[:, b]
        )
        ends.append((cross, p, key))
    cross = np.stack([c for c, _, _ in ends], axis=1)
    ok = cross.sum(axis=1) == 2
    order = np.argsort(~cross[ok], axis=1, kind="stable")[:, :2]
    pts = np.stack([p[ok] for _, p, _ in ends], axis=1)
    keys = np.stack([k[ok] for _, _, k in ends], axis=1)
    rows = np.arange(len(order))[:, None]
    return pts[rows, order], keys[rows, order]


def _isoline_islands(vertices, faces, g, levels):
    """For each of ``levels``, the islands of the isoline g == level: a list of (segment lengths (K,),
    segment mids (K, 3)) per level, islands of at least 3 segments in the order of their first end.

    The disjoint set of every level's segments is one graph (nodes offset level by level), so the
    connected components are found once, not once per level (the sparse set-up cost ~1 ms a call)."""
    segs = [_isoline_segments(vertices, faces, g, level) for level in levels]
    invs, offset = [], 0
    for _, seg_k in segs:
        uniq, inv = np.unique(seg_k.ravel(), return_inverse=True)
        invs.append(inv.reshape(-1, 2) + offset)
        offset += len(uniq)
    both = np.concatenate(invs) if invs else np.zeros((0, 2), np.int64)
    graph = coo_matrix((np.ones(len(both)), (both[:, 0], both[:, 1])), shape=(offset, offset))
    _, lab = connected_components(graph, directed=False)  # the disjoint set of isoline segments
    out = []
    for (seg_p, _), inv in zip(segs, invs):
        seg_lab = lab[inv[:, 0]]
        lengths = np.linalg.norm(seg_p[:, 1] - seg_p[:, 0], axis=1)
        mids = seg_p.mean(axis=1)
        islands = []
        for island in np.unique(seg_lab):
            sel = seg_lab == island
            if sel.sum() >= 3 and lengths[sel].sum() > 0:
                islands.append((lengths[sel], mids[sel]))
        out.append(islands)
    return out


def _link_levels(vertices, faces, g, levels):
    """Splines as lists of (centroid, samples or None) and their parents, from the isoline islands."""
    base_pts = vertices[g <= 1e-12]
    splines: list[list] = [[(base_pts.mean(axis=0), None)]]
    parents, alive = [-1], [0]
    link = 0.0
    for islands in _isoline_islands(vertices, faces, g, levels):
        if not islands or not alive:
            break
        cents = np.array([(m * w[:, None]).sum(0) / w.sum() for w, m in islands])
        perim = np.array([w.sum() for w, _ in islands])
        ends = np.array([splines[s][-1][0] for s in alive])
        link = max(link, 3.0 * (levels[1] - levels[0]) + perim.max() / np.pi)
        d = np.linalg.norm(cents[:, None] - ends[None], axis=2)
        owner = np.argmin(d, axis=1)
        keep = d[np.arange(len(cents)), owner] <= link
        new_alive = []
        for a, s in enumerate(alive):
            mine = np.flatnonzero(keep & (owner == a))
            mine = mine[np.argsort(-perim[mine], kind="stable")]
            if len(mine) == 1:
                splines[s].append((cents[mine[0]], islands[mine[0]]))
                new_alive.append(s)
            for i in mine if len(mine) > 1 else []:
                splines.append([splines[s][-1], (cents[i], islands[i])])
                parents.append(s)
                new_alive.append(len(splines) - 1)
        alive = new_alive
    return splines, parents


def _add_tips(vertices, g, splines, parents, last_level):
    """Append to each childless spline the farthest-geodesic vertex in its region beyond the last isoline."""
    leaves = [s for s in range(len(splines)) if s not in parents]
    ends = np.array([splines[s][-1][0] for s in leaves])
    beyond = np.flatnonzero(g > last_level)
    if len(beyond) == 0:
        return leaves
    _, near = cKDTree(ends).query(vertices[beyond])
    for a, s in enumerate(leaves):
        mine = beyond[near == a]
        if len(mine):
            tip = vertices[mine[np.argmax(g[mine])]]
            if np.linalg.norm(tip - splines[s][-1][0]) > 1e-9:
                splines[s].append((tip, None))
    return leaves


def _tangents_radii(pts: np.ndarray, samples: list) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (K, 3) by finite differences and radii (K,) as mean island distance to the axis."""
    t = np.gradient(pts, axis=0) if len(pts) > 1 else np.array([[0.0, 0.0, 1.0]])
    t = t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    r = np.full(len(pts), np.nan)
    for k, smp in enumerate(samples):
        if smp is not None:
            w, m = smp
            rel = m - pts[k]
            radial = rel - (rel @ t[k])[:, None] * t[k]
            r[k] = (np.linalg.norm(radial, axis=1) * w).sum() / w.sum()
    return t, r


def extract_skeleton(vertices: np.ndarray, faces: np.ndarray, levels: int = 32) -> ModuleSkeleton:
    """Skeleton of a branch mesh (V, 3) / (F, 3) whose base lies on its lowest plane (Appendix A)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) < 4 or vertices.ndim != 2 or vertices.shape[1] != 3:
        raise InputError("module mesh: needs (V, 3) vertices and at least 4 faces")
    extent = np.ptp(vertices, axis=0).max()
    sources = np.flatnonzero(vertices[:, 2] <= vertices[:, 2].min() + 1e-3 * extent)
    g = dijkstra(_edge_graph(vertices, faces), directed=False, indices=sources, min_only=True)
    g[sources] = 0.0
    values = g.max() * np.arange(1, levels) / levels
    splines, parents = _link_levels(vertices, faces, g, values)
    leaves = _add_tips(vertices, g, splines, parents, values[-1])
    pts, rad, tan, sid, tips = [], [], [], [], []
    for s, sp in enumerate(splines):
        p = np.array([c for c, _ in sp])
        t, r = _tangents_radii(p, [smp for _, smp in sp])
        if s > 0:
            r[0] = rad[sid.index(parents[s]) + len([x for x in sid if x == parents[s]]) - 1]
        r = _fill_nan(r)
        pts.append(p), rad.extend(r), tan.append(t), sid.extend([s] * len(p))
        if s in leaves:
            tips.append(len(sid) - 1)
    tangent = np.concatenate(tan)
    return ModuleSkeleton(
        points=np.concatenate(pts),
        radius=np.asarray(rad),
        tangent=tangent,
        spline=np.asarray(sid, dtype=np.int32),
        spline_parent=np.asarray(parents, dtype=np.int32),
        base=splines[0][0][0].copy(),
        base_direction=tangent[0].copy(),
        tips=np.asarray(tips, dtype=np.int32),
    )


def _fill_nan(r: np.ndarray) -> np.ndarray:
    """Replace NaN radii by the nearest measured value along the spline."""
    ok = np.flatnonzero(~np.isnan(r))
    if len(ok) == 0:
        return np.zeros_like(r)
    idx = np.arange(len(r))
    return r[ok[np.abs(idx[:, None] - ok[None]).argmin(axis=1)]]
