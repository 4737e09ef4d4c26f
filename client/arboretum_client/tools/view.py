"""What to draw for a ``ClientState``: a ``Scene`` (plain data) plus a touch index, rebuilt only when
``state.scene_version`` changes, and the small overlay (hands, strokes, drag preview) rebuilt when the
hands move.

Pick names: modeling 'inst:NAME/branch:I' and 'inst:NAME/lobe:J'; refinement 'branch:I', 'lobe:J',
'points'. Grown twigs and leaves are drawn but not pickable.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from arboretum_client.assembly_view import placed_hbl
from arboretum_client.render.meshes import uv_sphere
from arboretum_client.scene import InstancedMesh, Mesh, PointSet, Polyline, Scene, grid_for_bounds
from arboretum_client.scene_build import LEAF_COLOR, HBLStyle, hbl_items
from arboretum_library.model import HBL, Level

from .state import REFINEMENT, ClientState

FLASH_COLOR = (1.0, 0.85, 0.1)
SELECT_COLOR = (1.0, 0.95, 0.3)
CLOUD_LOBE_TINT = 0.5


@dataclass(frozen=True)
class TouchIndex:
    """Sample points of every pickable item, for touch-ball proximity (VR hands)."""

    points: np.ndarray
    """(K, 3) float64 world points."""
    ids: np.ndarray
    """(K,) int32 pick id of each point."""

    def nearest(self, p: np.ndarray, radius: float) -> int | None:
        if not len(self.points):
            return None
        d = np.linalg.norm(self.points - p, axis=1)
        k = int(d.argmin())
        return int(self.ids[k]) if d[k] <= radius else None


def _prefix(items, names, prefix: str):
    return items, {k: f"{prefix}{v}" for k, v in names.items()}


def mark_selected(items: list, names: dict[int, str], selection: list[str]) -> list:
    """Selected items drawn in ``SELECT_COLOR``: a selected example's branches, a selected lobe's hull."""
    if not selection:
        return items
    out = []
    for it in items:
        name = names.get(it.pick_id, "")
        hit = name in selection or name.split("/")[0] in selection
        if hit and isinstance(it, Polyline):
            it = dataclasses.replace(it, color=np.array([*SELECT_COLOR, 1.0], np.float32))
        elif hit and isinstance(it, Mesh):
            it = dataclasses.replace(it, color=np.array([*SELECT_COLOR, 0.6], np.float32))
        out.append(it)
    return out


def modeling_items(state: ClientState, now: float):
    """Items and names of every placement shown (all, or only the selected one)."""
    items, names, pid = [], {}, 1
    sel = {n.split("/")[0] for n in state.selection}
    for p in state.assembly.placements:
        ex = state.examples.get(p.example_id)
        if ex is None or (not state.show_all and sel and f"inst:{p.instance}" not in sel):
            continue
        its, nms = hbl_items(placed_hbl(ex.structure, p), HBLStyle(grid=False), first_id=pid)
        if state.merged_flash.get(p.instance, 0.0) > now:
            its = [dataclasses.replace(it, color=np.array([*FLASH_COLOR, it.color[3]], np.float32))
                   if isinstance(it, Polyline) and it.color[0] > 0.5 else it for it in its]
        its, nms = _prefix(its, nms, f"inst:{p.instance}/")
        items += its
        names.update(nms)
        pid = max(nms) + 1 if nms else pid
    items = mark_selected(items, names, state.selection) + _merge_links(state)
    return items, names, pid


def _merge_links(state: ClientState) -> list:
    """A yellow line for each recombination link between two placements' main branches."""
    where = {}
    for p in state.assembly.placements:
        ex = state.examples.get(p.example_id)
        if ex is not None:
            where[p.instance] = placed_hbl(ex.structure, p).branches[0].points
    out = []
    for m in state.assembly.merges:
        if m.a in where and m.b in where:
            a = where[m.a][min(m.vertex_a, len(where[m.a]) - 1)]
            b = where[m.b][min(m.vertex_b, len(where[m.b]) - 1)]
            if np.linalg.norm(a - b) > 1e-6:
                out.append(Polyline(points=_f32(np.stack([a, b])), radii=_f32(np.zeros(2)), color=_f32(FLASH_COLOR),
                                    style="line", width_px=4.0))
    return out


def _focus_branches(hbl: HBL, focus: int) -> set[int]:
    """Branch indices of the example rooted at the ``focus``-th main branch (its secondaries too)."""
    mains = [i for i, b in enumerate(hbl.branches) if b.level == Level.MAIN]
    root = mains[focus % len(mains)] if mains else 0
    keep = {root}
    for i, b in enumerate(hbl.branches):
        if b.parent in keep and b.level != Level.MAIN:
            keep.add(i)
    return keep


def refinement_items(state: ClientState):
    """Draft branches and lobes (all, or the focused example only) and the point cloud."""
    hbl = state.draft
    if hbl is None:
        return [], {}, 1
    items, names = hbl_items(hbl, HBLStyle(grid=False))
    if not state.show_all:
        keep = _focus_branches(hbl, state.focus)
        lobe_keep = {j for j, lb in enumerate(hbl.lobes) if lb.branch in keep}
        pairs = [(it, n) for it, (pid, n) in zip(items, names.items())
                 if (n.startswith("branch:") and int(n[7:]) in keep) or (n.startswith("lobe:") and int(n[5:]) in lobe_keep)]
        items, names = [it for it, _ in pairs], {it.pick_id: n for it, n in pairs}
    items = mark_selected(items, names, state.selection)
    pid = max(names, default=0) + 1
    cloud = state.cloud
    if state.show_points and cloud is not None and len(cloud.points):
        items.append(PointSet(points=cloud.points, colors=cloud_colors(state), size_px=2.0, pick_id=pid))
        names[pid] = "points"
        pid += 1
    return items, names, pid


def cloud_colors(state: ClientState) -> np.ndarray:
    """(N, 3) point colours: a lobe's points in its palette colour, others wood brown / leaf green,
    the point selection (for 'insert lobe') in ``SELECT_COLOR``."""
    from arboretum_client.scene_build import LOBE_PALETTE, WOOD_COLOR

    cloud = state.cloud
    assert cloud is not None
    colors = np.where(cloud.labels[:, None] == 1, LEAF_COLOR, WOOD_COLOR).astype(np.float32)
    palette = np.asarray(LOBE_PALETTE, np.float32)
    lobed = cloud.lobe_of >= 0
    colors[lobed] = palette[cloud.lobe_of[lobed] % len(palette)] * 0.8
    if len(state.point_selection):
        colors[state.point_selection] = SELECT_COLOR
    return colors


def grown_items(state: ClientState) -> list:
    """Twigs as one batch of thin lines and leaves as instanced quads (not pickable)."""
    g = state.grown
    if g is None or not len(g.positions):
        return []
    child = np.nonzero(g.parents >= 0)[0]
    twig = _f32((0.36, 0.25, 0.15))
    items: list = [Polyline(points=_f32(np.stack([g.positions[g.parents[c]], g.positions[c]])), radii=_f32(np.zeros(2)),
                            color=twig, style="line", width_px=1.5) for c in child]
    if len(g.leaf_centres):
        quad = Mesh(vertices=np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], np.float32),
                    faces=np.array([[0, 1, 2], [0, 2, 3]], np.int32), color=_f32((*LEAF_COLOR, 1.0)))
        items.append(InstancedMesh(mesh=quad, matrices=leaf_matrices(g.leaf_centres, g.leaf_normals, g.leaf_sizes)))
    return items


def leaf_matrices(centres: np.ndarray, normals: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """(K, 4, 4) T_world_leaf: the unit quad's +Z turned onto each normal, scaled by the size."""
    n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0, 0, 1.0]], [[1.0, 0, 0]])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)
    M = np.zeros((len(n), 4, 4))
    M[:, :3, 0], M[:, :3, 1], M[:, :3, 2] = u * sizes[:, None], v * sizes[:, None], n * sizes[:, None]
    M[:, :3, 3], M[:, 3, 3] = centres, 1.0
    return M


def build_scene(state: ClientState, now: float = 0.0) -> tuple[Scene, TouchIndex]:
    if state.mode == REFINEMENT:
        items, names, _ = refinement_items(state)
    else:
        items, names, _ = modeling_items(state, now)
    items = list(items) + grown_items(state)
    scene = Scene(items=tuple(items), names=names)
    grid = grid_for_bounds(scene.bounds()) if items else grid_for_bounds(np.array([[-1, -1, 0], [1, 1, 2.0]]))
    return dataclasses.replace(scene, grid=grid), touch_index(scene)


def touch_index(scene: Scene) -> TouchIndex:
    pts, ids = [], []
    for it in scene.items:
        if it.pick_id <= 0 or isinstance(it, PointSet):
            continue
        p = it.vertices if isinstance(it, Mesh) else it.points if isinstance(it, Polyline) else np.zeros((0, 3))
        if isinstance(it, Mesh):
            p = np.concatenate([p, p.mean(axis=0, keepdims=True)])
        pts.append(np.asarray(p, np.float64))
        ids.append(np.full(len(p), it.pick_id, np.int32))
    if not pts:
        return TouchIndex(np.zeros((0, 3)), np.zeros(0, np.int32))
    return TouchIndex(np.concatenate(pts), np.concatenate(ids))


_BALL = uv_sphere(8, 12)


def _f32(values) -> np.ndarray:
    return np.asarray(values, np.float32)


def hand_ball(position: np.ndarray, radius: float, color) -> Mesh:
    v, f = _BALL
    return Mesh(vertices=(v * radius + position).astype(np.float32), faces=f, color=_f32((*color, 1.0)))
