"""Sketch a new example from 3D strokes (VRTree 3.5, "sketch new example", after Zhang et al. 2021).

Recognition: a stroke whose ends meet (a closed loop) or that doubles back on itself (a scribble:
straight distance between its ends under ``straightness`` of its length) is a lobe; any other stroke,
long and roughly linear, is a branch. The longest branch stroke becomes the main branch (grown from its
lower end); other branch strokes become secondary branches attached at the nearest main vertex; each
lobe stroke becomes an ellipsoid hull along the stroke's principal axes, fed by the branch stroke that
ends nearest it, or by a new straight secondary branch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from arboretum_library.descriptors import describe, tags_for
from arboretum_library.errors import InputError
from arboretum_library.geometry import make_transform, polyline_lengths, resample_polyline
from arboretum_library.model import HBL, Branch, Example, Level, Lobe, Provenance

BRANCH, LOBE = "branch", "lobe"


@dataclass(frozen=True)
class SketchOptions:
    """How strokes are read."""

    closed: float = 0.25
    """A stroke whose ends are closer than this fraction of its length is a closed loop (lobe)."""
    straightness: float = 0.5
    """A stroke whose end-to-end distance is below this fraction of its length is a scribble (lobe)."""
    spacing: float = 0.05
    """Vertex spacing of sketched branches, metres."""
    main_radius: tuple[float, float] = (0.04, 0.01)
    """Radius of a sketched main branch at its base and tip, metres."""
    secondary_radius: tuple[float, float] = (0.012, 0.004)
    """Radius of a sketched secondary branch at its base and tip, metres."""
    min_lobe_radius: float = 0.03
    """Smallest semi-axis of a sketched lobe hull, metres."""


def recognise(stroke: np.ndarray, o: SketchOptions = SketchOptions()) -> str:
    """'branch' or 'lobe' for one stroke (S, 3)."""
    s = np.asarray(stroke, dtype=np.float64).reshape(-1, 3)
    length = polyline_lengths(s)[-1] if len(s) >= 2 else 0.0
    if length <= 1e-6:
        raise InputError(f"sketch: a stroke of {len(s)} samples has no length")
    chord = float(np.linalg.norm(s[-1] - s[0]))
    return LOBE if chord < o.closed * length or chord < o.straightness * length else BRANCH


def _polyline(s: np.ndarray, spacing: float) -> np.ndarray:
    n = max(2, int(np.ceil(polyline_lengths(s)[-1] / spacing)) + 1)
    return resample_polyline(s, n)


def _taper(n: int, r: tuple[float, float]) -> np.ndarray:
    return np.linspace(r[0], r[1], n)


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    g = (1 + 5**0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g], [0, -1, -g],
                  [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], float)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], np.int32)
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    inward = (normals * v[f].mean(axis=1)).sum(axis=1) < 0
    f[inward] = f[inward][:, ::-1]
    return v, f


def lobe_hull(stroke: np.ndarray, o: SketchOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centre (3,), hull vertices (12, 3), faces (20, 3)): an ellipsoid along the stroke's principal axes."""
    c = stroke.mean(axis=0)
    _, sv, axes = np.linalg.svd(stroke - c, full_matrices=False)
    if np.linalg.det(axes) < 0:
        axes[2] *= -1
    radii = np.maximum(sv * 2.0 / np.sqrt(len(stroke)), o.min_lobe_radius)
    v, f = _icosahedron()
    return c, c + (v * radii) @ axes, f


def sketch_example(strokes: Sequence[np.ndarray], example_id: str,
                   o: SketchOptions = SketchOptions()) -> tuple[Example, np.ndarray, tuple[str, ...]]:
    """An example from ``strokes`` (each (S_k, 3), world frame): (example in a frame at its root,
    T_world_example (4, 4), the kind of each stroke)."""
    strokes = [np.asarray(s, dtype=np.float64).reshape(-1, 3) for s in strokes]
    kinds = tuple(recognise(s, o) for s in strokes)
    branch_strokes = sorted((s for s, k in zip(strokes, kinds) if k == BRANCH), key=lambda s: -polyline_lengths(s)[-1])
    if not branch_strokes:
        raise InputError("sketch: draw at least one branch stroke (a long, roughly straight line)")
    main = _polyline(branch_strokes[0], o.spacing)
    if main[-1, 2] < main[0, 2]:
        main = main[::-1]
    root = main[0].copy()
    branches = [Branch(main - root, _taper(len(main), o.main_radius))]
    tips = []
    for s in branch_strokes[1:]:
        d0, d1 = (np.linalg.norm(main - p, axis=1).min() for p in (s[0], s[-1]))
        s = s if d0 <= d1 else s[::-1]
        pv = int(np.argmin(np.linalg.norm(main - s[0], axis=1)))
        poly = _polyline(s, o.spacing)
        if np.linalg.norm(poly[0] - main[pv]) < 1e-6:
            poly = poly[1:]
        pts = np.vstack([main[pv], poly])
        branches.append(Branch(pts - root, _taper(len(pts), o.secondary_radius), 0, pv, Level.SECONDARY))
        tips.append(pts[-1])
    lobes = _lobes([s for s, k in zip(strokes, kinds) if k == LOBE], main, tips, branches, root, o)
    hbl = HBL(np.zeros(3), tuple(branches), tuple(lobes))
    d = describe(hbl)
    ex = Example(example_id, hbl, Provenance("sketch"), d, tags_for(d) + ("sketch",))
    return ex, make_transform(t=root), kinds


def _lobes(strokes: list[np.ndarray], main: np.ndarray, tips: list[np.ndarray], branches: list[Branch],
           root: np.ndarray, o: SketchOptions) -> list[Lobe]:
    """A lobe per lobe stroke, fed by the nearest free branch tip or a new secondary branch."""
    lobes, fed = [], set()
    for s in strokes:
        c, verts, faces = lobe_hull(s, o)
        reach = 1.5 * float(np.linalg.norm(verts - c, axis=1).max())
        near = [(float(np.linalg.norm(t - c)), k + 1) for k, t in enumerate(tips) if k + 1 not in fed]
        best = min(near, default=(np.inf, -1))
        if best[0] <= reach:
            feed = best[1]
        else:
            pv = int(np.argmin(np.linalg.norm(main - c, axis=1)))
            pts = main[pv] + np.linspace(0, 1, 4)[:, None] * (c - main[pv])
            if np.linalg.norm(c - main[pv]) < 1e-6:
                pts = pts + np.linspace(0, 1e-3, 4)[:, None] * np.array([1.0, 0, 0])
            branches.append(Branch(pts - root, _taper(4, o.secondary_radius), 0, pv, Level.SECONDARY))
            feed = len(branches) - 1
        fed.add(feed)
        lobes.append(Lobe(np.zeros((0, 3)), verts - root, faces, c - root, feed))
    return lobes
