"""Accuracy of a decomposition against ground truth (synthetic trees) or a reference skeleton (QSM).

All distances are in the HBL's output frame; ``to_frame`` maps scan/truth coordinates into it. Figures:

- ``main_fit``: mean distance from points sampled along the N_m longest true branches to the nearest
  extracted main branch, as a fraction of tree height (target <= 0.02); ``main_fit_worst``: the worst
  single branch's mean.
- ``main_fit_seen``: the same over what a scan can show: each true branch only where a scan point lies
  within ``SEEN_TOL`` of the height of its surface, i.e. within its radius plus ``SEEN_TOL`` x height of
  its axis (a missing sector hides branches), ranked by that seen length, and true
  branches whose lengths are within ``TIE`` of the N_m-th longest are interchangeable (the best of them
  fill the set). Where branches tie, "the N_m longest" is a matter of millimetres: on the harmonic pine
  the 5th to 7th longest first-order branches differ by 0.6 % of their length, less than one 1 cm vertex
  step of the extraction, and measuring lengths on resampled polylines reorders them.
- ``main_precision``: mean distance from the extracted main branches to the nearest true branch of any
  order (do extracted main branches follow real wood?).
- ``leaf_cover``: fraction of true leaf points inside a lobe hull or within 1 cm (0.8 m scale) of one.
- ``counts_ok``: N_m main branches and N_l lobes exactly; ``connected``: every branch reaches branch 0
  through parents and starts on its parent's vertex.
- ``crossings``: secondary branches with a vertex more than ``CROSS_TOL`` inside a lobe they do not feed.
- ``main_turning`` / ``secondary_turning``: mean turning angle (radians) per interior vertex of the main /
  secondary branches (smoothness: graph-path zig-zag turns about 0.5 rad at every vertex).
- ``main_drop``: the deepest fall of a main branch below the highest point it reached before, as a
  fraction of the height (0 for branches that never turn down; a trunk path that climbs one limb and
  comes down to reach another is a hook no tree grows).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from arboretum_library.geometry import polyline_lengths
from arboretum_library.model import HBL, Level
from arboretum_library.truth import TreeTruth, branch_polylines, polyline_length

from .merge import drop, resample_step, sample_polylines

COVER_TOL = 0.01
"""Leaf cover tolerance at the 0.8 m scale."""
SEEN_TOL = 0.01
"""A true branch point is seen when a scan point lies within this fraction of the height of its surface."""
TIE = 0.05
"""True branch lengths within this fraction of the N_m-th longest's are interchangeable (``main_fit_seen``)."""
CROSS_TOL = 0.002
"""How deep (0.8 m scale) a secondary branch may enter a foreign lobe before it counts as crossing."""


@dataclass(frozen=True)
class Metrics:
    main_fit: float
    main_fit_worst: float
    main_fit_seen: float
    main_precision: float
    leaf_cover: float
    n_main: int
    n_lobes: int
    counts_ok: bool
    connected: bool
    crossings: int
    main_turning: float
    secondary_turning: float
    main_drop: float

    def as_dict(self) -> dict:
        return asdict(self)


def signed_distances(vertices: np.ndarray, faces: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Signed distance (M,) of ``q`` (M, 3) to the closed mesh; negative inside (open3d ray casting)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32)))
    return scene.compute_signed_distance(o3d.core.Tensor(q.astype(np.float32))).numpy().astype(np.float64)


def lobe_distance(hbl: HBL, q: np.ndarray, skip: Callable[[int], bool] = lambda j: False) -> np.ndarray:
    """Smallest signed distance (M,) from ``q`` to any lobe hull of ``hbl`` (inf where none is near)."""
    best = np.full(len(q), np.inf)
    for j, lobe in enumerate(hbl.lobes):
        if skip(j):
            continue
        lo, hi = lobe.hull_vertices.min(axis=0), lobe.hull_vertices.max(axis=0)
        pad = 0.05 * max(hbl.height, 1e-9)
        near = np.flatnonzero(((q > lo - pad) & (q < hi + pad)).all(axis=1))
        if len(near):
            best[near] = np.minimum(best[near], signed_distances(lobe.hull_vertices, lobe.hull_faces, q[near]))
    return best


def main_fit(per: list[tuple[np.ndarray, np.ndarray]], longest: np.ndarray, height: float) -> tuple[float, float]:
    """(mean, worst-branch mean) distance / ``height`` of the true branches ``longest`` (indices into
    ``branch_distances``' output ``per``) to the MAIN branches, seen or not."""
    d = [per[i][0] for i in longest]
    if not d:
        return 0.0, 0.0
    return float(np.concatenate(d).mean() / height), float(max(x.mean() for x in d) / height)


def turning_angles(polyline: np.ndarray) -> np.ndarray:
    """(L-2,) angle (radians) between consecutive edges at each interior vertex of ``polyline`` (L, 3)."""
    e = np.diff(polyline, axis=0)
    n = np.linalg.norm(e, axis=1)
    e = e[n > 1e-12] / n[n > 1e-12, None]
    return np.arccos(np.clip((e[:-1] * e[1:]).sum(axis=1), -1.0, 1.0))


def mean_turning(hbl: HBL, level: Level) -> float:
    """Mean turning angle (radians) per interior vertex over the branches of ``level``."""
    a = [turning_angles(hbl.branches[i].points) for i in hbl.by_level(level)]
    a = np.concatenate(a) if a else np.zeros(0)
    return float(a.mean()) if len(a) else 0.0


def main_drop(hbl: HBL) -> float:
    """The largest fall of a main branch below its running highest point, / height (``main_drop``)."""
    falls = [drop(hbl.branches[i].points) for i in hbl.by_level(Level.MAIN)]
    return max(falls, default=0.0) / max(hbl.height, 1e-12)


def connected(hbl: HBL) -> bool:
    """True if every branch reaches branch 0 and starts at its parent's ``parent_vertex``."""
    for b in hbl.branches[1:]:
        if b.parent < 0:
            return False
        if np.linalg.norm(b.points[0] - hbl.branches[b.parent].points[b.parent_vertex]) > 1e-9 * max(hbl.height, 1.0):
            return False
    return len(hbl.branches) > 0 and hbl.branches[0].parent == -1


def crossings(hbl: HBL) -> int:
    """Secondary branches with a vertex more than CROSS_TOL (0.8 m scale) inside a lobe they do not feed."""
    tol = CROSS_TOL * hbl.height / 0.8
    feeds = {lb.branch: j for j, lb in enumerate(hbl.lobes)}
    bad = 0
    for i in hbl.by_level(Level.SECONDARY):
        own = feeds.get(i, -1)
        pts = resample_step(hbl.branches[i].points, tol)
        if (lobe_distance(hbl, pts, lambda j, own=own: j == own) < -tol).any():
            bad += 1
    return bad


def branch_distances(hbl: HBL, true_branches: list[np.ndarray], scan: np.ndarray,
                     radii: list[np.ndarray] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each true branch (in the HBL frame): (distances (M,) of its samples every height/500 to the
    nearest main branch, seen (M,) bool: a ``scan`` point (P, 3) within ``SEEN_TOL`` of the height of
    the branch's surface). ``radii``: each branch's radius per vertex in the same frame (None: 0, the
    axis; a trunk thicker than ``SEEN_TOL`` of the height then never counts as seen)."""
    h = max(hbl.height, 1e-12)
    mains = cKDTree(sample_polylines([hbl.branches[i].points for i in hbl.by_level(Level.MAIN)], h / 500))
    seen = cKDTree(scan) if len(scan) else None
    out = []
    for j, b in enumerate(true_branches):
        q = resample_step(b, h / 500)
        if seen is None:
            ok = np.zeros(len(q), bool)
        else:
            s = polyline_lengths(b)
            r = np.interp(np.linspace(0.0, s[-1], len(q)), s, radii[j]) if radii is not None else 0.0
            ok = seen.query(q)[0] <= r + SEEN_TOL * h
        out.append((mains.query(q)[0], ok))
    return out


def main_fit_seen(per: list[tuple[np.ndarray, np.ndarray]], lengths: np.ndarray, n_main: int, height: float) -> float:
    """``main_fit_seen`` (see the module doc) from ``branch_distances`` and the true lengths (B,)."""
    seen = np.array([lengths[i] * ok.mean() if len(ok) else 0.0 for i, (_, ok) in enumerate(per)])
    order = np.argsort(-seen)
    cut = seen[order[min(n_main, len(order)) - 1]] if len(order) else 0.0
    need = [int(i) for i in order[:n_main] if seen[i] > cut * (1 + TIE)]
    pool = [int(i) for i in order if cut * (1 - TIE) <= seen[i] <= cut * (1 + TIE) and seen[i] > 0]
    def mean(i: int) -> float:
        return float(per[i][0][per[i][1]].mean())
    chosen = need + sorted(pool, key=mean)[: max(0, n_main - len(need))]
    d = [per[i][0][per[i][1]] for i in chosen]
    return float(np.concatenate(d).mean() / height) if d else 0.0


def main_precision(hbl: HBL, true_branches: list[np.ndarray]) -> float:
    """Mean distance from the main branches (sampled every height/500) to any true branch / height."""
    h = max(hbl.height, 1e-12)
    truth = cKDTree(sample_polylines(true_branches, h / 500))
    mains = sample_polylines([hbl.branches[i].points for i in hbl.by_level(Level.MAIN)], h / 500)
    return float(truth.query(mains)[0].mean() / h) if len(mains) else 0.0


def evaluate(hbl: HBL, truth: TreeTruth, leaf_points: np.ndarray, to_frame: Callable[[np.ndarray], np.ndarray],
             n_main: int, n_lobes: int, scan_points: np.ndarray | None = None) -> Metrics:
    """Metrics of ``hbl`` against ``truth``; ``leaf_points`` (L, 3), ``scan_points`` (P, 3) (all the
    scan's points; None: every true point counts as seen) and the truth are in the scan frame.
    ``to_frame`` must be a similarity (uniform scale): the true radii are scaled by its unit length."""
    polys = branch_polylines(truth)
    lengths = np.array([polyline_length(truth, p) for p in polys])
    branches = [to_frame(truth.positions[p]) for p in polys]
    scan = to_frame(np.asarray(scan_points, np.float64).reshape(-1, 3)) if scan_points is not None else None
    unit = float(np.linalg.norm(to_frame(np.eye(3)[:1]) - to_frame(np.zeros((1, 3)))))
    radii = [truth.radii[p] * unit for p in polys]
    per = branch_distances(hbl, branches, scan if scan is not None else np.concatenate(branches), radii)
    h = max(hbl.height, 1e-12)
    fit, worst = main_fit(per, np.argsort(-lengths)[:n_main], h)
    seen = main_fit_seen(per, lengths, n_main, h)
    tol = COVER_TOL * hbl.height / 0.8
    leaves = to_frame(np.asarray(leaf_points, dtype=np.float64).reshape(-1, 3))
    cover = float((lobe_distance(hbl, leaves) <= tol).mean()) if len(leaves) else 1.0
    nm, nl = len(hbl.by_level(Level.MAIN)), len(hbl.lobes)
    return Metrics(fit, worst, seen, main_precision(hbl, branches), cover, nm, nl,
                   nm == n_main and nl == n_lobes, connected(hbl), crossings(hbl),
                   mean_turning(hbl, Level.MAIN), mean_turning(hbl, Level.SECONDARY), main_drop(hbl))


def reference_fit(hbl: HBL, starts: np.ndarray, ends: np.ndarray) -> dict[str, float]:
    """skeleton_fit-style figures of the HBL's branches against reference segments (in the HBL frame)."""
    h = max(hbl.height, 1e-12)
    ref = sample_polylines([np.stack([a, b]) for a, b in zip(starts, ends)], h / 500)
    mains = [hbl.branches[i].points for i in hbl.by_level(Level.MAIN)]
    cand_main = sample_polylines(mains, h / 500)
    cand_all = sample_polylines([b.points for b in hbl.branches], h / 500)
    d_main = cKDTree(cand_main).query(ref)[0]
    d_all = cKDTree(cand_all).query(ref)[0]
    return {
        "ref_to_main": float(d_main.mean() / h),
        "ref_to_all": float(d_all.mean() / h),
        "main_to_ref": float(cKDTree(ref).query(cand_main)[0].mean() / h),
        "ref_covered_all": float((d_all < 0.02 * h).mean()),
    }
