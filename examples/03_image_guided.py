"""Image-guided modeling (VRTree 4.2, Fig. 9): place library examples so the tree matches a reference image.

The reference image is the front silhouette of a tree that is not in the library: a harmonic oak,
scanned by the virtual scanner, scaled to the library's 0.8 m, drawn headless as black dots seen from
the front and closed into a mask (256 x 256). The client has no reference-image billboard, so the
picture shows the mask as a flat quad mesh (one quad per mask pixel, unprojected onto a plane behind the
tree). Standing in for the user, a greedy loop places examples from three libraries (harmonic walnut,
cherry and apple, each decomposed with its species): first the trunk example, turned and scaled, that
best matches the mask; then, up to ``STEPS`` times, the example, attachment vertex on the trunk,
turn about the vertical and scale that most raise the intersection over union (IoU) of the occupied
cells (a coarse 64 x 64 grid of the projected example points) with the mask. The placed examples are
joined to the trunk by Algorithm 1 and the assembled HBL's silhouette (branch tubes and lobe hulls,
opaque black) is rendered with the same camera and compared with the reference mask. The baseline places
the same examples at the same heights with random turns and scales.

    python examples/03_image_guided.py --out out/image --seed 0
"""

from __future__ import annotations

import time

import numpy as np
from _common import (
    attach,
    axis_angle_matrix,
    camera_for,
    emit,
    iou,
    labelled,
    library,
    parse_args,
    render,
    save,
    side_by_side,
    silhouette,
    source,
    structure_items,
    synth_scan,
)

SIZE = (256, 256)
CELL = 4
"""Pixels per side of a cell of the placement loop's occupancy grid."""
STEPS = 16
NEIGHBOURS = ((0, 0),)
"""Cells each projected point fills besides its own (none: the cell grid is already coarse)."""
ANGLES = np.arange(0.0, 360.0, 45.0)
SCALES = (0.6, 0.85, 1.1)
LIBRARIES = ("walnut", "cherry", "apple")


def reference(seed: int):
    """(mask (H, W) bool, camera, target points): the oak's front silhouette at the 0.8 m scale."""
    from scipy.ndimage import binary_closing, binary_fill_holes

    from arboretum_client.scene import PointSet

    pts, _ = synth_scan("oak", seed + 21)
    base = np.r_[np.median(pts[pts[:, 2] < np.quantile(pts[:, 2], 0.03), :2], axis=0), pts[:, 2].min()]
    pts = (pts - base) * (0.8 / np.ptp(pts[:, 2]))
    dots = [PointSet(points=pts.astype(np.float32), colors=np.zeros((len(pts), 3), np.float32), size_px=3.0)]
    cam = camera_for(dots, SIZE, "front", margin=1.15)
    mask = silhouette(dots, SIZE, cam)
    mask = binary_fill_holes(binary_closing(mask, np.ones((5, 5), bool), iterations=2))
    return mask, cam, pts


def samples(example, n: int = 400, rng: np.random.Generator | None = None) -> np.ndarray:
    """(<= n + branch vertices, 3) points of an example relative to its main branch's base."""
    s = example.structure
    lobe = np.concatenate([np.r_[lb.points, lb.hull_vertices] for lb in s.lobes]) if s.lobes else np.zeros((0, 3))
    if len(lobe) > n:
        lobe = lobe[(rng or np.random.default_rng(0)).choice(len(lobe), n, replace=False)]
    return np.r_[lobe, np.concatenate([b.points for b in s.branches])] - s.branches[0].points[0]


def occupancy(points: np.ndarray, cam) -> np.ndarray:
    """(..., G*G) bool cells hit by ``points`` (..., n, 3) (and the NEIGHBOURS offsets)."""
    g = SIZE[0] // CELL
    lead = points.shape[:-2]
    px = cam.project(points.reshape(-1, 3), SIZE).reshape(*lead, -1, 2) // CELL
    ok = (px >= 0).all(-1) & (px < g).all(-1)
    occ = np.zeros((int(np.prod(lead)), g + 2, g + 2), bool)
    flat = np.broadcast_to(np.arange(len(occ)).reshape(lead)[..., None], ok.shape)
    ix, iy = px[..., 0].astype(int) + 1, px[..., 1].astype(int) + 1
    for dx, dy in NEIGHBOURS:
        occ[flat[ok], iy[ok] + dy, ix[ok] + dx] = True
    return occ[:, 1:-1, 1:-1].reshape(*lead, g * g)


def poses(q: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """(A, S, K, n, 3): ``q`` (n, 3) turned by ANGLES, scaled by SCALES, its base put on each anchor (K, 3)."""
    Rs = np.stack([axis_angle_matrix(np.array([0.0, 0, 1]), np.radians(a)) for a in ANGLES])
    turned = np.einsum("aij,nj->ani", Rs, q)
    scaled = turned[:, None] * np.asarray(SCALES)[None, :, None, None]
    return scaled[:, :, None] + anchors[None, None, :, None, :]


def best_pose(examples: list, anchors: np.ndarray, cover: np.ndarray, t: np.ndarray, cam, rng: np.random.Generator):
    """(cell IoU, example, (angle, scale, anchor) indices, cells) of the best single placement added to
    ``cover`` (G*G,) against the target cells ``t`` (G*G,)."""
    best = None
    for ex in examples:
        occ = occupancy(poses(samples(ex, rng=rng), anchors), cam) | cover
        score = (occ & t).sum(-1) / (occ | t).sum(-1)
        k = np.unravel_index(int(np.argmax(score)), score.shape)
        if best is None or score[k] > best[0]:
            best = (float(score[k]), ex, k, occ[k])
    return best


def greedy(trunks: list, pool: list, target: np.ndarray, cam, rng: np.random.Generator):
    """Placements [(example, angle, scale, anchor (3,))] chosen greedily for the cell IoU, and the IoUs."""
    t = target.reshape(-1)
    empty = np.zeros_like(t)
    first = [best_pose([ex], ex.structure.branches[0].points[:1], empty, t, cam, rng) for ex in trunks]
    iou0, trunk, (a, s, _), cover = max(first, key=lambda b: b[0])
    base = trunk.structure.branches[0].points[0]
    chosen, ious = [(trunk, ANGLES[a], SCALES[s], base)], [iou0]
    R = axis_angle_matrix(np.array([0.0, 0, 1]), np.radians(ANGLES[a]))
    main = (trunk.structure.branches[0].points - base) @ R.T * SCALES[s] + base
    anchors = main[np.linspace(0.25 * len(main), len(main) - 1, 8).astype(int)]
    for _ in range(STEPS):
        pool = [ex for ex in pool if ex.id not in {c[0].id for c in chosen}]
        step = best_pose(pool, anchors, cover, t, cam, rng) if pool else None
        if step is None or step[0] <= ious[-1] + 1e-3:
            break
        ious.append(step[0])
        cover = step[3]
        a, s, k = step[2]
        chosen.append((step[1], ANGLES[a], SCALES[s], anchors[k]))
    return chosen, ious


def assemble(chosen: list, get):
    """The assembly of the chosen placements (turn about the base, scale, base on the anchor), joined."""
    from arboretum_library.assembly import Assembly
    from arboretum_library.geometry import make_transform
    from arboretum_server.assembly import ops
    from arboretum_server.assembly.recombine import RecombineOptions

    a = Assembly()
    for k, (ex, angle, scale, anchor) in enumerate(chosen):
        R = axis_angle_matrix(np.array([0.0, 0, 1]), np.radians(angle))
        T = make_transform(R, anchor - scale * (R @ ex.structure.branches[0].points[0]))
        a, _ = ops.add_example(a, get, ex.id, T, scale, f"p{k}", RecombineOptions(enabled=False))
        if k:
            a = attach(a, get, f"p{k}")
    return a


def billboard(mask: np.ndarray, cam, y: float) -> list:
    """The mask as a flat mesh: one quad per mask pixel, unprojected onto the plane Y = ``y``."""
    from arboretum_client.scene import Mesh

    h, w = mask.shape
    iy, ix = np.nonzero(mask)
    corners = np.stack([np.c_[ix + dx, iy + dy] for dx, dy in ((0, 0), (1, 0), (1, 1), (0, 1))], axis=1).reshape(-1, 2)
    ndc = np.c_[corners[:, 0] / w * 2 - 1, 1 - corners[:, 1] / h * 2]
    inv = np.linalg.inv(cam.projection_matrix(w / h) @ cam.view_matrix())
    far = np.c_[ndc, np.ones(len(ndc)), np.ones(len(ndc))] @ inv.T
    far = far[:, :3] / far[:, 3:]
    eye = cam.eye
    t = (y - eye[1]) / (far[:, 1] - eye[1])
    verts = eye + t[:, None] * (far - eye)
    q = np.arange(len(iy))[:, None] * 4
    faces = np.r_[np.c_[q, q + 1, q + 2], np.c_[q, q + 2, q + 3]].astype(np.int32)
    return [Mesh(vertices=verts.astype(np.float32), faces=faces, color=np.float32([0.55, 0.62, 0.72, 1.0]))]


def main() -> None:
    args = parse_args(__doc__)
    t0 = time.perf_counter()
    from arboretum_server.assembly.world import assembly_to_hbl

    rng = np.random.default_rng(args.seed)
    mask, cam, target_pts = reference(args.seed)
    libs = [library(*synth_scan(sp, args.seed + 31 + k), sp, sp, args.seed)[1] for k, sp in enumerate(LIBRARIES)]
    get = source(*libs)
    g = SIZE[0] // CELL
    coarse = mask.reshape(g, CELL, g, CELL).mean(axis=(1, 3)) >= 0.5
    chosen, ious = greedy([lib[0] for lib in libs], [e for lib in libs for e in lib[1:]], coarse, cam, rng)
    hbl = assembly_to_hbl(assemble(chosen, get), get)
    result = silhouette(structure_items(hbl), SIZE, cam)
    trunk_only = silhouette(structure_items(assembly_to_hbl(assemble(chosen[:1], get), get)), SIZE, cam)
    rand = [(ex, float(rng.uniform(0, 360)), float(rng.uniform(SCALES[0], SCALES[-1])), anchor) for ex, _, _, anchor in chosen]
    random_mask = silhouette(structure_items(assembly_to_hbl(assemble(chosen[:1] + rand[1:], get), get)), SIZE, cam)
    figures = {"placed": len(chosen), "library": sum(len(lib) for lib in libs), "mask_pixels": int(mask.sum()),
               "iou": round(iou(result, mask), 4), "iou_trunk_only": round(iou(trunk_only, mask), 4),
               "iou_random_placement": round(iou(random_mask, mask), 4),
               "iou_cells_per_step": [round(x, 4) for x in ious], "examples": [c[0].id for c in chosen]}
    pictures(args, mask, cam, hbl, result, figures)
    emit({"experiment": "image_guided", "seed": args.seed, **figures, "pictures": ["image_guided.png"],
          "seconds": round(time.perf_counter() - t0, 2)})


def pictures(args, mask, cam, hbl, result, figures: dict) -> None:
    """Reference mask | HBL in front of the billboard | masks overlaid (green both, grey reference, red result)."""
    from arboretum_client.scene import Scene

    y_back = float(Scene(items=tuple(structure_items(hbl))).bounds()[1][1]) + 0.05
    ref = np.where(mask[..., None], np.uint8([40, 40, 40]), np.uint8([245, 245, 245]))
    over = np.full((*mask.shape, 3), 245, np.uint8)
    over[mask & ~result], over[result & ~mask], over[mask & result] = (170, 170, 170), (220, 40, 40), (40, 150, 60)
    panels = [labelled(ref, "reference silhouette (oak)"),
              labelled(render(billboard(mask, cam, y_back) + structure_items(hbl, lobe_alpha=0.8), SIZE, cam),
                       f"{figures['placed']} examples\non the billboard"),
              labelled(over, f"IoU {figures['iou']:.3f}\n(random turns {figures['iou_random_placement']:.3f})")]
    save(side_by_side(panels), args.out / "image_guided.png")


if __name__ == "__main__":
    main()
