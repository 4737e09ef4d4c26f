"""Reconstruction from an incomplete point cloud (VRTree 4.3, Fig. 10): fill a scan's gap with its own examples.

The bundled synthetic scan ``guiding_default_s1_missing90.ply`` lacks a 90 degree azimuth wedge. It is
decomposed (species default: N_m = 8, N_l = 40, in the scan's own metres) into a small library. The
skeleton-only reconstruction is that decomposed HBL as it is. The filled one places the whole tree at its
original pose and then, standing in for the user, finds the gap (the widest empty run of 10 degree azimuth
bins of the scan around the root) and puts turned copies of examples from the intact side into it:
one per 20 degrees of gap, each the unused example whose foliage lies nearest in azimuth to the gap's
side, turned about the vertical through the root so its foliage centre lands on its target azimuth,
and joined to the tree by Algorithm 1. Both are compared with the COMPLETE scan of the same tree
(``guiding_default_s1.ply``): coverage is the fraction of its points within d of the reconstruction,
where the distance to a branch is the distance to its nearest axis sample (every d / 4) minus the
branch radius, and the distance to a lobe the distance to its nearest point or hull vertex.

    python examples/04_incomplete_scan.py --out out/incomplete --seed 0
"""

from __future__ import annotations

import math
import time

import numpy as np
from _common import (
    attach,
    emit,
    labelled,
    library,
    parse_args,
    render,
    rot_z,
    save,
    side_by_side,
    source,
    structure_items,
    synth_asset,
)

D_FRACTIONS = (0.01, 0.02, 0.05)
"""Coverage distances d as fractions of the complete scan's height (2 % is the headline)."""
SPACING = 20.0
"""Degrees of gap per copied example."""
SIZE = (420, 420)
COPY_RGBA = (0.10, 0.35, 0.95, 1.0)


def foliage_azimuth(example, root: np.ndarray) -> float:
    """Degrees: azimuth about ``root`` of the mean of the example's lobe points (its main tip if none)."""
    s = example.structure
    c = np.concatenate([lb.points for lb in s.lobes]).mean(axis=0) if s.lobes else s.branches[0].points[-1]
    return math.degrees(math.atan2(c[1] - root[1], c[0] - root[0])) % 360


def find_gap(points: np.ndarray, root: np.ndarray, bin_deg: float = 10.0) -> tuple[float, float]:
    """(start, width) in degrees of the widest run of empty azimuth bins of ``points`` about ``root``
    (points within 20 % of the crown radius of the root's vertical are left out: near the trunk the
    azimuth is noise)."""
    rel = points[:, :2] - root[:2]
    r = np.linalg.norm(rel, axis=1)
    rel = rel[r > 0.2 * r.max()]
    az = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360
    n = int(round(360 / bin_deg))
    empty = np.bincount((az // bin_deg).astype(int) % n, minlength=n) == 0
    best, run, start = (0, 0), 0, 0
    for k in range(2 * n):  # twice round, so a run through 0 degrees counts whole
        if empty[k % n]:
            run, start = run + 1, start if run else k
            best = max(best, (min(run, n), start))
        else:
            run = 0
    return (best[1] % n) * bin_deg, best[0] * bin_deg


def fill(examples: list, get, root: np.ndarray, gap: tuple[float, float]):
    """The whole tree at its pose plus turned copies of intact-side examples in the gap: (assembly, copies)."""
    from arboretum_library.assembly import Assembly
    from arboretum_server.assembly import ops
    from arboretum_server.assembly.recombine import RecombineOptions

    off = RecombineOptions(enabled=False)
    a = Assembly()
    for ex in examples:
        a, _ = ops.add_example(a, get, ex.id, np.eye(4), 1.0, ex.id, off)
    start, width = gap
    n = max(1, int(round(width / SPACING)))
    targets = [start + (k + 0.5) * width / n for k in range(n)]
    used: set[str] = set()
    for k, target in enumerate(targets):
        side = start - 0.5 * width if target < start + width / 2 else start + 1.5 * width  # the nearer intact side
        pool = [e for e in examples[1:] if e.id not in used and e.structure.lobes]
        ex = min(pool, key=lambda e: abs((foliage_azimuth(e, root) - side + 180) % 360 - 180))
        used.add(ex.id)
        T = rot_z(target - foliage_azimuth(ex, root), root)
        a, _ = ops.add_example(a, get, ex.id, T, 1.0, f"copy{k}", off)
        a = attach(a, get, f"copy{k}")
    return a, len(targets)


def distances(hbl, points: np.ndarray, d: float) -> np.ndarray:
    """(N,) distance of each point to the nearest branch surface (axis sample minus radius) or lobe sample."""
    from scipy.spatial import cKDTree

    from arboretum_library.geometry import polyline_lengths, resample_polyline

    samples, radii = [], []
    for b in hbl.branches:
        n = max(2, int(polyline_lengths(b.points)[-1] / (d / 4)) + 1)
        samples.append(resample_polyline(b.points, n))
        s = polyline_lengths(b.points)
        radii.append(np.interp(np.linspace(0, s[-1], n), s, b.radii))
    for lb in hbl.lobes:
        samples += [lb.points, lb.hull_vertices]
        radii += [np.zeros(len(lb.points)), np.zeros(len(lb.hull_vertices))]
    S, R = np.concatenate(samples), np.concatenate(radii)
    dist, idx = cKDTree(S).query(points, k=8)
    return np.maximum(dist - R[idx], 0.0).min(axis=1)


def main() -> None:
    args = parse_args(__doc__)
    t0 = time.perf_counter()
    from arboretum_server.assembly.world import assembly_to_hbl

    partial, labels = synth_asset("guiding_default_s1_missing90.ply")
    complete, _ = synth_asset("guiding_default_s1.ply")
    dec, examples = library(partial, labels, "default", "missing90", args.seed, height=None, points_used=12000)
    get = source(examples)
    root = dec.hbl.root
    gap = find_gap(partial, root)
    filled, copies = fill(examples, get, root, gap)
    filled_hbl = assembly_to_hbl(filled, get)
    height = float(np.ptp(complete[:, 2]))
    az = np.degrees(np.arctan2(complete[:, 1] - root[1], complete[:, 0] - root[0])) % 360
    in_gap = (az - gap[0]) % 360 < gap[1]
    cover = {}
    for name, hbl in (("skeleton_only", dec.hbl), ("filled", filled_hbl)):
        for f in D_FRACTIONS:
            near = distances(hbl, complete, f * height) <= f * height
            cover[f"{name}_d{f:g}"] = round(float(near.mean()), 4)
            cover[f"{name}_gap_d{f:g}"] = round(float(near[in_gap].mean()), 4)
    figures = {"gap_start_deg": gap[0], "gap_width_deg": gap[1], "copies": copies, "examples": len(examples),
               "complete_points": len(complete), "gap_points": int(in_gap.sum()), "height": round(height, 3),
               "d": round(0.02 * height, 4), "coverage": cover,
               "gain_d0.02": round(cover["filled_d0.02"] - cover["skeleton_only_d0.02"], 4),
               "branches": {"skeleton_only": len(dec.hbl.branches), "filled": len(filled_hbl.branches)},
               "lobes": {"skeleton_only": len(dec.hbl.lobes), "filled": len(filled_hbl.lobes)}}
    pictures(args.out, partial, complete, dec.hbl, filled_hbl, height, cover)
    emit({"experiment": "incomplete_scan", "seed": args.seed, **figures, "pictures": ["incomplete.png"],
          "seconds": round(time.perf_counter() - t0, 2)})


def pictures(out, partial, complete, skeleton, filled, height: float, cover: dict) -> None:
    """Top views: the incomplete scan | skeleton-only | filled, complete-scan points red where uncovered."""
    from arboretum_client.camera import fit_camera
    from arboretum_client.scene import PointSet

    def dots(p, rgb, px=2.0):
        return PointSet(points=p.astype(np.float32), colors=np.tile(np.float32(rgb), (len(p), 1)), size_px=px)

    cam = fit_camera(np.stack([complete.min(axis=0), complete.max(axis=0)]), "top", 1.0)
    d = 0.02 * height
    panels = [labelled(render([dots(partial, (0.2, 0.3, 0.45))], SIZE, cam, grid=False),
                      "incomplete scan (90 deg missing), top")]
    for name, hbl in (("skeleton only", skeleton), ("filled", filled)):
        far = distances(hbl, complete, d) > d
        items = structure_items(hbl) + [dots(complete[far], (0.9, 0.1, 0.1), 3.0)]
        key = "skeleton_only" if name == "skeleton only" else "filled"
        panels.append(labelled(render(items, SIZE, cam, grid=False),
                               f"{name}: {cover[key + '_d0.02']:.1%} of complete scan\nwithin d (red: not)"))
    save(side_by_side(panels), out / "incomplete.png")


if __name__ == "__main__":
    main()
