"""``arboretum modules`` at any crown size: modules and trunk follow the crown, the reach is told truthfully.

The same crown shape at 0.2 m, 8 m or 200 m must give the same tree, scaled (the paper's lengths are in
scene units); the trunk's top a third of the way up the crown; a sparsely filled crown gets a note.
"""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pygltflib
import pytest

from arboretum_library.cli import main
from arboretum_library.codec import load_record, save_record
from arboretum_library.export.instanced import EXTENSION
from arboretum_library.model import HBL
from arboretum_server.modules.meshio import save_obj
from arboretum_server.modules.shapes import sphere_mesh

SCAN = "assets/scans/01_rtwig_coffeetree/01_rtwig_coffeetree.xyz"


def _modules(argv: list[str], capsys) -> dict:
    assert main(["modules", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _trunk_top(glb) -> tuple[float, float]:
    """(top, base) height (Z up) of the trunk instance of an EXT_mesh_gpu_instancing GLB (Y up)."""
    g = pygltflib.GLTF2().load(str(glb))
    blob = g.binary_blob()

    def acc(i: int) -> np.ndarray:
        a = g.accessors[i]
        v = g.bufferViews[a.bufferView]
        width = {"VEC3": 3, "VEC4": 4}[a.type]
        return np.frombuffer(blob, np.float32, a.count * width, v.byteOffset + (a.byteOffset or 0)).reshape(-1, width)

    k = next(i for i, n in enumerate(g.nodes) if n.mesh is not None and g.meshes[n.mesh].name.startswith("trunk"))
    node = g.nodes[k]
    attrs = node.extensions[EXTENSION]["attributes"]
    offset = sum(np.asarray(p.translation or [0.0] * 3) for p in g.nodes if k in (p.children or []))  # recentring
    t, s = acc(attrs["TRANSLATION"])[0] + offset, acc(attrs["SCALE"])[0]
    top_y = g.accessors[g.meshes[node.mesh].primitives[0].attributes.POSITION].max[1]
    return float(t[1] + s[1] * top_y), float(t[1])


def _scaled_hbl(h: HBL, k: float) -> HBL:
    from dataclasses import replace

    branches = tuple(replace(b, points=b.points * k, radii=b.radii * k) for b in h.branches)
    lobes = tuple(replace(lb, points=lb.points * k, hull_vertices=lb.hull_vertices * k, centre=lb.centre * k)
                  for lb in h.lobes)
    return replace(h, root=h.root * k, branches=branches, lobes=lobes, points=h.points * k)


def _quiet_modules(argv: list[str]) -> dict:
    """``_modules`` for a module-scoped fixture (no capsys there): the JSON summary ``modules`` prints."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["modules", *argv, "--json"]) == 0
    return json.loads(out.getvalue())


def _sphere_run(folder, centre: list[float], r: float) -> dict:
    """``modules --crown`` on a sphere of radius r (seed 1): its summary, the trunk's (top, base) and the
    crown's (lo, hi) heights as written to the OBJ."""
    v, f = sphere_mesh(centre, r)
    name = f"c{r}_{'_'.join(f'{c:g}' for c in centre)}"
    save_obj(folder / f"{name}.obj", v, f)
    lo, hi = np.round(v[:, 2], 5).min(), np.round(v[:, 2], 5).max()  # as written to the OBJ
    s = _quiet_modules(["--crown", str(folder / f"{name}.obj"), "--out", str(folder / f"{name}.glb"), "--seed", "1"])
    return {"summary": s, "trunk": _trunk_top(folder / f"{name}.glb"), "z": (lo, hi), "v": v}


@pytest.fixture(scope="module")
def sphere_3m(tmp_path_factory) -> dict:
    """The reference run of the any-size test, made once for both sizes (it was made once per size)."""
    return _sphere_run(tmp_path_factory.mktemp("sphere3"), [0, 0, 6.0], 3.0)


@pytest.mark.parametrize("radius", [0.1, 100.0])
def test_a_sphere_crown_gives_the_same_tree_at_any_size(tmp_path, sphere_3m, radius):
    """Sphere of radius 3 m at z = 6 m (reference) against the same shape at r = 0.1 m and r = 100 m."""
    s = {}
    for r in (3.0, radius):
        run = sphere_3m if r == 3.0 else _sphere_run(tmp_path, [0, 0, 2 * r], r)
        (lo, hi), (top, base) = run["z"], run["trunk"]
        s[r] = run["summary"]
        assert base == pytest.approx(lo - (hi - lo) / 4, abs=1e-6 * r)  # a quarter of the crown below it
        assert top == pytest.approx(lo + (hi - lo) / 3, rel=1e-4)  # a third of the way up the crown
    ref, other = s[3.0], s[radius]
    assert ref["modules_placed"] > 50 and ref["constraints"]["reached_fraction"] > 0.85
    assert 0.8 < other["modules_placed"] / ref["modules_placed"] < 1.25
    assert other["constraints"]["reached_fraction"] > 0.85 and not other["notes"]
    assert other["module_scale"] / ref["module_scale"] == pytest.approx(radius / 3.0)


@pytest.fixture(scope="module")
def coffee(tmp_path_factory):
    """The documented pipeline: ``decompose`` at the default 0.8 m, and the same tree at 8 m and 0.08 m."""
    d = tmp_path_factory.mktemp("coffee")
    assert main(["decompose", SCAN, "--save-hbl", str(d / "c0.8.npz"), "--seed", "1", "--json"]) == 0
    h = load_record(d / "c0.8.npz", HBL)
    for k in (10, 0.1):
        save_record(d / f"c{0.8 * k:g}.npz", _scaled_hbl(h, k))
    return d


@pytest.fixture(scope="module")
def coffee_modules(coffee) -> dict[str, tuple[dict, tuple[float, float]]]:
    """``modules --assembly`` (seed 2) on the coffee tree at each size: size -> (summary, trunk (top, base)).
    Made once: the 0.8 m run was made twice, here and by the poorly-filled test, with the same arguments."""
    runs = {}
    for size in ("0.8", "8", "0.08"):
        out = coffee / f"m{size}.glb"
        runs[size] = (_quiet_modules(["--assembly", str(coffee / f"c{size}.npz"), "--out", str(out), "--seed", "2"]),
                      _trunk_top(out))
    return runs


def test_a_decomposed_tree_gives_the_same_modular_tree_at_any_size(coffee, coffee_modules):
    runs = {}
    for size in ("0.8", "8", "0.08"):
        runs[size], (top, base) = coffee_modules[size]
        h = load_record(coffee / f"c{size}.npz", HBL)
        z = np.concatenate([lb.hull_vertices[:, 2] for lb in h.lobes])
        assert base == pytest.approx(h.branches[0].points[0][2], abs=1e-5 * float(size))
        assert top == pytest.approx(z.min() + (z.max() - z.min()) / 3, rel=1e-3)
    counts = [r["modules_placed"] for r in runs.values()]
    assert min(counts) >= 10 and max(counts) <= 1.25 * min(counts)
    reached = [r["constraints"]["reached_fraction"] for r in runs.values()]
    assert max(reached) - min(reached) < 0.1


def test_a_poorly_filled_crown_says_so(tmp_path, coffee, coffee_modules, capsys):
    """The coffee tree's 40 small, separate lobe hulls are filled sparsely: a note, not a success line."""
    out = tmp_path / "m.glb"
    s = coffee_modules["0.8"][0]  # the --json run of these arguments
    reached = s["constraints"]["reached_fraction"]
    assert reached < 0.5 and len(s["notes"]) == 1 and f"only {100 * reached:.0f}%" in s["notes"][0]
    assert main(["modules", "--assembly", str(coffee / "c0.8.npz"), "--out", str(out), "--seed", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and lines[1].startswith("note: only ")


def test_the_fitted_trunk_does_not_reach_a_small_crown_alone():
    """d_k is a fraction of the trunk-and-crown box (paper); with the trunk fitted to a 0.2 m crown it is
    small, so the trunk alone reaches few attraction points (before: the 3.4 m trunk at scale >= 0.5 made
    d_k larger than the crown, "100 % reached" by the trunk alone)."""
    from arboretum_server.modules.fit import default_module_set, grow_in_crown
    from arboretum_server.modules.options import ModularTreeOptions

    v, f = sphere_mesh([0, 0, 0.2], 0.1)
    opt = ModularTreeOptions(max_iterations=0)
    tree, modules, k = grow_in_crown(default_module_set(), [(v, f)], [0, 0, 0], opt, np.random.default_rng(1))
    assert tree.stats.modules_placed == 1 and 0.005 < k < 0.05
    T = tree.T_world_module[0]
    trunk = modules.modules[int(tree.module[0])]
    world = trunk.vertices @ T[:3, :3].T + T[:3, 3]
    top = world[:, 2].max()
    assert top == pytest.approx(v[:, 2].min() + np.ptp(v[:, 2]) / 3, rel=1e-9)
    skeleton = trunk.skeleton.points @ T[:3, :3].T + T[:3, 3]
    d = np.linalg.norm(tree.attraction_points[:, None] - skeleton[None], axis=2).min(axis=1)
    d_kill = opt.kill_fraction * float(np.ptp(np.concatenate([world, v]), axis=0).max())
    np.testing.assert_array_equal(tree.reached, d <= d_kill)
    assert tree.stats.reached_fraction < 0.2


@pytest.fixture(scope="module")
def sphere_4m_near(tmp_path_factory) -> dict:
    """The near-the-ground run of the high-crown test, made once for both positions (it was made once per
    position)."""
    return _sphere_run(tmp_path_factory.mktemp("sphere4"), [0.0, 0.0, 6.0], 4.0)


@pytest.mark.parametrize("xyz", [(0.0, 0.0, 310.0), (512345.0, 4123456.0, 316.0)])
def test_a_crown_high_above_z0_gets_the_tree_it_gets_near_the_ground(tmp_path, sphere_4m_near, xyz):
    """An r = 4 m sphere at z = 6 m (trunk on z = 0) against the same sphere 310 m up or at UTM xy: before,
    the trunk stood on z = 0, ×88 (313 m), and d_k covered the crown from the trunk alone (1 module, "100 %")."""
    from arboretum_server.modules.fit import crown_root

    runs = {}
    for c in ((0.0, 0.0, 6.0), xyz):
        run = sphere_4m_near if c == (0.0, 0.0, 6.0) else _sphere_run(tmp_path, list(c), 4.0)
        runs[c], (top, base), (lo, hi) = run["summary"], run["trunk"], run["z"]
        assert base == pytest.approx(max(0.0, lo - (hi - lo) / 4), abs=1e-3)
        assert base == pytest.approx(crown_root(run["v"])[2], abs=1e-3)
        assert top == pytest.approx(lo + (hi - lo) / 3, abs=1e-3)
    near, far = runs[(0.0, 0.0, 6.0)], runs[xyz]
    assert near["modules_placed"] > 100 and near["constraints"]["reached_fraction"] > 0.85
    assert 0.9 <= far["modules_placed"] / near["modules_placed"] <= 1.1
    assert abs(far["constraints"]["reached_fraction"] - near["constraints"]["reached_fraction"]) < 0.05
    assert far["module_scale"] == pytest.approx(near["module_scale"]) and not far["notes"]


def test_a_trunk_far_below_the_crown_is_bounded():
    """A root 300 m under an 8 m crown: the trunk is at most ``max_trunk_fraction`` crown heights long."""
    from arboretum_server.modules.crown import crown_from_meshes
    from arboretum_server.modules.fit import FitOptions, default_module_set, trunk_transform

    modules = default_module_set()
    crown = crown_from_meshes([sphere_mesh([0, 0, 306], 4.0)], 16)
    trunk = modules.modules[int(modules.trunk_indices[0])]
    T = trunk_transform(modules, crown, [0, 0, 0])
    height = T[2, 2] * trunk.vertices[:, 2].max()
    assert height == pytest.approx(FitOptions().max_trunk_fraction * np.ptp(crown.bounds[:, 2]), rel=1e-9)
    T = trunk_transform(modules, crown, [0, 0, 300])  # near: a third of the way up the crown
    assert T[2, 2] * trunk.vertices[:, 2].max() == pytest.approx(crown.bounds[0, 2] + np.ptp(crown.bounds[:, 2]) / 3
                                                                   - 300, rel=1e-9)


def test_a_trunk_only_tree_always_gets_a_note(tmp_path, capsys, monkeypatch):
    """Only the trunk placed: a note even when its branching points "reach" every attraction point."""
    import functools

    import arboretum_server.modules.options as options
    from arboretum_server.modules.fit import reach_note

    assert reach_note(1.0) is None and reach_note(0.4).startswith("only 40%")
    assert reach_note(1.0, 1).startswith("only the trunk was placed") and "100%" in reach_note(1.0, 1)
    assert reach_note(1.0, 2) is None
    v, f = sphere_mesh([0, 0, 6], 4.0)
    save_obj(tmp_path / "c.obj", v, f)
    monkeypatch.setattr(options, "ModularTreeOptions",
                        functools.partial(options.ModularTreeOptions, max_iterations=0))
    s = _modules(["--crown", str(tmp_path / "c.obj"), "--out", str(tmp_path / "t.glb")], capsys)
    assert s["modules_placed"] == 1 and len(s["notes"]) == 1 and s["notes"][0].startswith("only the trunk")
