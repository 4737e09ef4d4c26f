"""Guiding-vector trees: graph, lazy Dijkstra, rules, ground truth (Xu and Mould 2015)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from arboretum_library.errors import InputError, ValidationError
from arboretum_library.geometry import quat_to_matrix
from arboretum_library.truth import (
    TreeTruth,
    branch_polylines,
    leaf_card_corners,
    load_truth,
    pipe_model_radii,
    save_truth,
)
from arboretum_server.synth.endpoints import Volume
from arboretum_server.synth.fields import Rotation, field_angles, incremental_angles, vectors
from arboretum_server.synth.guiding import (
    GuidingOptions,
    Iteration,
    build_graph,
    grow_guiding,
    grow_paths,
    path_stretch,
)
from arboretum_server.synth.kernels import knn, throw_darts
from arboretum_server.synth.paths import (
    CsrGraph,
    FlatGraph,
    lazy_dijkstra,
    lazy_search,
    reference_search,
)
from arboretum_server.synth.poisson import first_independent_set, poisson_disc, spacing_for_count
from arboretum_server.synth.presets import preset
from arboretum_server.synth.skeleton import matrix_to_wxyz
from arboretum_server.synth.yao import _cell_size, sector_of, yao_graph

TOP = Volume("box", (0.0, 0.0, 4.5), (2.5, 2.5, 1.2))


def _grow_one(alpha: float, sectors: int = 14, nodes: int = 15000, seed: int = 5):
    opts = GuidingOptions(width=6, height=6, nodes=nodes, sectors=sectors,
                          iterations=(Iteration(Rotation("piecewise", alpha, alpha, 0), endpoints=30, volume=TOP),))  # fmt: skip
    rng = np.random.default_rng(seed)
    g, root = build_graph(opts, rng)
    return g, root, grow_paths(g, root, opts, rng)


def _tips(st) -> np.ndarray:
    kids = np.bincount(st.parent[st.parent >= 0], minlength=len(st.parent))
    return np.flatnonzero(st.in_tree & (kids == 0))


def test_poisson_disc_spacing_and_count(rng):
    pts = poisson_disc(np.zeros(3), np.ones(3) * 2, 0.1, rng)
    d, _ = cKDTree(pts).query(pts, 2)
    assert d[:, 1].min() >= 0.1
    assert 0.3 * 8 / 0.1**3 < len(pts) < 0.5 * 8 / 0.1**3  # DENSITY 0.386 per r^3
    assert pts.min() >= 0 and pts.max() <= 2


def test_yao_edges_are_the_nearest_per_sector(rng):
    pts = rng.random((400, 3))
    for sectors in (8, 14, 26):
        g = yao_graph(pts, sectors, k=399)
        vec = pts[None, :, :] - pts[:, None, :]
        sec = sector_of(vec, sectors)
        dist = np.linalg.norm(vec, axis=2) + np.eye(len(pts)) * 1e9
        for u in range(0, 400, 37):
            for s in range(sectors):
                inside = np.flatnonzero(sec[u] == s)
                inside = inside[inside != u]
                want = inside[np.argmin(dist[u, inside])] if len(inside) else u
                assert g.neighbours[u, s] == want


def test_lazy_dijkstra_matches_scipy_on_a_fixed_field(rng):
    pts = rng.random((1500, 3)) * 3
    g = yao_graph(pts, 14)
    theta, phi = field_angles(Rotation("helical", pitch=40.0), pts, np.array([1.5, 1.5, 0.0]))
    v = vectors(theta, phi)
    w = np.maximum(g.lengths - (g.vectors * v[:, None, :]).sum(axis=2), 1e-12 * g.lengths)
    rows = np.repeat(np.arange(len(pts)), 14)
    keep = g.neighbours.ravel() != rows
    mat = csr_matrix(
        (w.ravel()[keep], (rows[keep], g.neighbours.ravel()[keep])), shape=(1500, 1500)
    )
    ref = dijkstra(mat, indices=0)
    cg = CsrGraph.of(g)
    for got in (
        lazy_dijkstra(FlatGraph.of(cg), np.array([0]), theta, phi, None, None, 0),
        lazy_search(cg, np.array([0]), theta, phi, None, None, 0),
    ):
        fin = np.isfinite(ref)
        assert fin.sum() > 1400 and np.array_equal(got.done, fin)
        assert np.allclose(got.cost[fin], ref[fin], rtol=1e-9, atol=1e-12)


def test_lazy_vectors_follow_eq1():
    g, root, st = _grow_one(0.0, nodes=6000)
    fg = FlatGraph.of(CsrGraph.of(g))
    n = len(g.points)
    a1, a2, h0 = np.radians(12.0), np.radians(-4.0), 3
    res = lazy_dijkstra(
        fg, np.array([root]), np.zeros(n), np.zeros(n), np.full(n, a1), np.full(n, a2), h0
    )
    u = np.flatnonzero(res.parent >= 0)
    p = res.parent[u]
    want = np.clip(res.theta[p] + np.where(res.hops[u] <= h0, a1, a2), 0, np.pi)
    assert np.allclose(res.theta[u], want)
    assert np.array_equal(res.hops[u], res.hops[p] + 1)
    tilted = res.theta[p] > 1e-9  # rotation about up x parent keeps the azimuth
    assert tilted.mean() > 0.3 and np.array_equal(res.phi[u[tilted]], res.phi[p[tilted]])
    assert res.done.all() and res.theta.max() == pytest.approx(3 * a1, abs=1e-12)


def _same_search(slow, fast) -> None:
    """The kernel's result is the reference's: identical tree, vectors within 1e-12."""
    assert np.array_equal(slow.parent, fast.parent) and np.array_equal(slow.origin, fast.origin)
    assert np.array_equal(slow.hops, fast.hops) and np.array_equal(slow.done, fast.done)
    assert np.allclose(slow.theta, fast.theta, rtol=0, atol=1e-12)
    assert np.allclose(slow.phi, fast.phi, rtol=0, atol=1e-12)
    fin = slow.done
    assert np.allclose(slow.cost[fin], fast.cost[fin], rtol=1e-12, atol=1e-12)
    assert np.isinf(fast.cost[~fin]).all()


def _rule_arrays(kind: str, pts: np.ndarray, rng: np.random.Generator):
    """theta, phi, near, far, h0 for ``kind`` as ``guiding._iterate`` makes them."""
    n = len(pts)
    theta, phi = np.zeros(n), np.zeros(n)
    theta[[0, 17, 400]], phi[[0, 17, 400]] = [0.0, 0.4, 1.2], [0.0, 2.0, -1.0]
    root = np.array([2.0, 2.0, 0.0])
    rot = {"eq1": Rotation("piecewise", 6.0, -6.0, 20), "eq1_h0_1": Rotation("piecewise", 30.0, 0.0, 1),
           "random": Rotation("random", alpha2=-3.0, h0=2), "eq2": Rotation("global", theta=25.0),
           "helical": Rotation("helical", pitch=30.0), "rotational": Rotation("rotational"),
           "spherical": Rotation("spherical")}[kind]  # fmt: skip
    if rot.kind in ("helical", "rotational", "spherical"):
        theta, phi = field_angles(rot, pts, root)
        return theta, phi, None, None, 0
    near, far, h0 = incremental_angles(rot, pts, root, rng)
    return theta, phi, near, far, h0


@pytest.mark.parametrize(
    "kind", ["eq1", "eq1_h0_1", "random", "eq2", "helical", "rotational", "spherical"]
)
@pytest.mark.parametrize("seed", [0, 1])
def test_kernel_search_equals_reference(kind, seed):
    """The numba kernel and the pure-Python reference give the same search, with and without targets."""
    rng = np.random.default_rng(seed)
    pts = rng.random((2500, 3)) * [4, 4, 5]
    cg = CsrGraph.of(yao_graph(pts, (14, 8)[seed]))
    sources = np.array([0, 17, 400])
    theta, phi, near, far, h0 = _rule_arrays(kind, pts, rng)
    for targets in (None, rng.choice(len(pts), 40, replace=False)):
        slow = reference_search(cg, sources, theta, phi, near, far, h0, targets)
        fast = lazy_search(cg, sources, theta, phi, near, far, h0, targets)
        _same_search(slow, fast)
        if targets is not None:  # early exit: all targets final, the rest of the graph not searched
            assert slow.done[targets].all() and slow.done.sum() < len(pts)
            assert slow.done[sources].all()
        else:
            assert slow.done.all()


def test_kernel_constants_are_the_references():
    from arboretum_server.synth import kernels, paths

    assert (kernels.PI, kernels.VERTICAL) == (paths.PI, paths.VERTICAL) == (np.pi, 1e-9)


@pytest.mark.parametrize("name", ["default", "hanging", "upward", "helical", "elm", "ash"])
def test_tree_with_kernel_equals_tree_with_reference(name):
    """Every preset (Eq. 1, hanging, upward, helical field, Eq. 2, random angle): same tree both ways."""
    opts = preset(name, nodes=5000)
    states = []
    for search in (lazy_search, reference_search):
        rng = np.random.default_rng(4)
        g, root = build_graph(opts, rng)
        states.append(grow_paths(g, root, opts, rng, search=search))
    fast, slow = states
    assert slow.in_tree.sum() > 500
    for f in ("in_tree", "parent", "root_hops", "generation"):
        assert np.array_equal(getattr(fast, f), getattr(slow, f)), f
    assert np.allclose(fast.theta, slow.theta, rtol=0, atol=1e-12)
    assert np.allclose(fast.phi, slow.phi, rtol=0, atol=1e-12)


def test_bundled_sample_truth_is_reproduced_exactly():
    """The kernels changed no result: assets/synth/guiding_default_s1_truth.npz grows again bit for bit."""
    from pathlib import Path

    ref = load_truth(Path(__file__).parents[1] / "assets/synth/guiding_default_s1_truth.npz")
    tr = grow_guiding(preset("default"), 1, "default")
    for f in ("positions", "parent", "radii", "branch_id", "leaf_positions", "leaf_wxyz"):
        assert np.array_equal(getattr(tr, f), getattr(ref, f)), f


def _poisson_darts(nodes: int, seed: int):
    lo, hi = np.array([-2.0, -2.0, 0.0]), np.array([2.0, 2.0, 3.0])
    r = spacing_for_count(hi - lo, nodes)
    rng = np.random.default_rng(seed)
    m = int(1.5 * np.prod(hi - lo) / r**3)
    return lo + rng.random((m, 3)) * (hi - lo), rng.permutation(m), lo, r


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dart_kernel_equals_independent_set_reference(seed):
    darts, prio, lo, r = _poisson_darts(8000, seed)
    pairs = cKDTree(darts).query_pairs(r, output_type="ndarray")
    ref = first_independent_set(prio, pairs[:, 0], pairs[:, 1])
    got = np.flatnonzero(throw_darts(darts, prio, lo, r))
    assert 7000 < len(ref) < 9000 and np.array_equal(got, ref)


@pytest.mark.parametrize("kind", ["poisson", "uniform", "flat"])
def test_knn_kernel_equals_ckdtree(kind):
    rng = np.random.default_rng(3)
    if kind == "poisson":
        pts = poisson_disc(np.zeros(3), np.array([3.0, 3.0, 4.0]), 0.12, rng)
    else:
        pts = rng.random((6000, 3)) * [3.0, 3.0, 4.0 if kind == "uniform" else 0.0]
    _, ref = cKDTree(pts).query(pts, 25)
    got = knn(pts, 24, _cell_size(pts))
    assert len(pts) > 4000 and np.array_equal(got, ref[:, 1:])


def _yao_reference(pts: np.ndarray, sectors: int, k: int) -> np.ndarray:
    """Yao neighbours by the vectorised rule: sort (sector, distance rank), first per sector."""
    n = len(pts)
    _, nb = cKDTree(pts).query(pts, k + 1)
    nb = nb[:, 1:]
    key = sector_of(pts[nb] - pts[:, None, :], sectors) * k + np.arange(k)
    key.sort(axis=1)
    s, col = key // k, key % k
    first = np.ones(s.shape, bool)
    first[:, 1:] = s[:, 1:] != s[:, :-1]
    rows = np.broadcast_to(np.arange(n)[:, None], s.shape)[first]
    out = np.broadcast_to(np.arange(n)[:, None], (n, sectors)).copy()
    out[rows, s[first]] = nb[rows, col[first]]
    return out


@pytest.mark.parametrize("sectors", [8, 14, 26])
def test_yao_kernel_equals_vectorised_reference(sectors):
    pts = poisson_disc(np.zeros(3), np.array([3.0, 3.0, 4.0]), 0.12, np.random.default_rng(sectors))
    g = yao_graph(pts, sectors)
    assert np.array_equal(g.neighbours, _yao_reference(pts, sectors, 24))
    evec = pts[g.neighbours] - pts[:, None, :]
    assert np.array_equal(g.vectors, evec)
    assert np.array_equal(g.lengths, np.linalg.norm(evec, axis=2))


def test_matrix_to_wxyz_roundtrip(rng):
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = np.stack([quat_to_matrix(x) for x in q])
    back = np.stack([quat_to_matrix(x) for x in matrix_to_wxyz(R)])
    assert np.abs(back - R).max() < 1e-12


def test_alpha_zero_paths_are_nearly_straight():
    """alpha = 0: cost = length - height gained, so paths are graph-shortest: stretch <= 1.15."""
    g, root, st = _grow_one(0.0)
    stretch = [path_stretch(g.points, st.parent, t, root) for t in _tips(st)]
    assert len(stretch) >= 20
    assert max(stretch) <= 1.15 and np.mean(stretch) <= 1.12
    g, root, st = _grow_one(25.0)
    bent = [path_stretch(g.points, st.parent, t, root) for t in _tips(st)]
    assert np.mean(bent) > np.mean(stretch) + 0.02  # measured 1.129 vs 1.092


def _rule_tree(rule: str):
    opts = preset("default", nodes=12000)
    its = opts.iterations[:2] + (
        Iteration(Rotation("piecewise", 30.0, 0.0, 1), endpoints=150, k=4, rule=rule),
    )
    opts = GuidingOptions(nodes=12000, iterations=its)
    rng = np.random.default_rng(11)
    g, root = build_graph(opts, rng)
    return g, grow_paths(g, root, opts, rng)


@pytest.mark.parametrize("rule", ["hanging", "upward"])
def test_endpoint_rules(rule):
    g, st = _rule_tree(rule)
    tips = [t for t in _tips(st) if st.generation[t] == 2]
    assert 0.8 * 150 <= len(tips) <= 150  # endpoint density: one branch per endpoint
    for t in tips:
        u = t
        while st.generation[st.parent[u]] == 2:
            u = st.parent[u]
        src = st.parent[u]
        assert (
            (g.points[t, 2] < g.points[src, 2])
            if rule == "hanging"
            else (g.points[t, 2] > g.points[src, 2])
        )


def _segment_distance(p1, q1, p2, q2):
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = (d1 * d1).sum(1), (d2 * d2).sum(1)
    b, c, f = (d1 * d2).sum(1), (d1 * r).sum(1), (d2 * r).sum(1)
    den = a * e - b * b
    safe = np.where(den > 1e-15, den, 1.0)
    s = np.where(den > 1e-15, np.clip((b * f - c * e) / safe, 0, 1), 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip((b * s + f) / e, 0, 1)
    return np.linalg.norm(p1 + d1 * s[:, None] - (p2 + d2 * t[:, None]), axis=1)


@pytest.mark.parametrize("name", ["default", "helical"])
def test_skeleton_never_self_intersects(name):
    """Non-adjacent edges stay > 0.2% of the median edge length apart (measured: 1.2% helical, 4.6% default)."""
    tr = grow_guiding(preset(name, nodes=15000), 2, name)
    ch = np.arange(1, tr.node_count)
    pa = tr.parent[ch]
    a, b = tr.positions[pa], tr.positions[ch]
    lengths = np.linalg.norm(b - a, axis=1)
    pairs = cKDTree((a + b) / 2).query_pairs(lengths.max(), output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    ends_i, ends_j = np.stack([pa[i], ch[i]], 1), np.stack([pa[j], ch[j]], 1)
    apart = ~(ends_i[:, :, None] == ends_j[:, None, :]).any(axis=(1, 2))
    d = _segment_distance(a[i[apart]], b[i[apart]], a[j[apart]], b[j[apart]])
    assert len(d) > 10000
    assert d.min() > 0.002 * np.median(lengths)


def test_seed_reproduces_tree_exactly():
    one = grow_guiding(preset("ash", nodes=8000), 7, "ash")
    two = grow_guiding(preset("ash", nodes=8000), 7, "ash")
    other = grow_guiding(preset("ash", nodes=8000), 8, "ash")
    for f in (
        "positions",
        "radii",
        "parent",
        "branch_id",
        "branch_order",
        "leaf_positions",
        "leaf_wxyz",
    ):
        assert np.array_equal(getattr(one, f), getattr(two, f)), f
    assert one.positions.shape != other.positions.shape or not np.array_equal(
        one.positions, other.positions
    )
    assert one.parameters == two.parameters and one.parameters["nodes"] == 8000


def _twist(tr: TreeTruth) -> float:
    """Mean signed azimuth change (radians) per metre along order-1 branches, about the trunk axis."""
    child = np.flatnonzero((tr.parent >= 0) & (tr.branch_order == 1))
    child = child[tr.branch_order[tr.parent[child]] == 1]
    rel = tr.positions - tr.positions[0]
    az = np.arctan2(rel[:, 1], rel[:, 0])
    daz = np.angle(np.exp(1j * (az[child] - az[tr.parent[child]])))
    far = np.hypot(rel[child, 0], rel[child, 1]) > 0.5
    step = np.linalg.norm(tr.positions[child] - tr.positions[tr.parent[child]], axis=1)
    return float(daz[far].sum() / step[far].sum())


def test_helical_field_twists_branches():
    helical = _twist(grow_guiding(preset("helical", nodes=15000), 3, "helical"))
    plain = _twist(grow_guiding(preset("default", nodes=15000), 3, "default"))
    assert helical > 0.15  # counter-clockwise about +Z
    assert abs(plain) < 0.05


def test_truth_is_valid_and_branches_are_chains():
    tr = grow_guiding(preset("default", nodes=10000), 1, "default")
    assert tr.parent[0] == -1 and (tr.parent[1:] < np.arange(1, tr.node_count)).all()
    lines = branch_polylines(tr)
    assert len(lines) == tr.branch_count and lines[0][0] == 0
    for ids in lines[1:20]:
        assert tr.branch_id[ids[0]] != tr.branch_id[ids[1]]
        assert (tr.parent[ids[1:]] == ids[:-1]).all()
    assert tr.radii[0] == tr.radii.max() and tr.leaf_count > 100
    assert (tr.branch_order[tr.leaf_node] >= 1).all()


def test_pipe_model_radii():
    parent = np.array([-1, 0, 1, 1, 0])
    r = pipe_model_radii(parent, 0.01, 2.0)
    assert np.allclose(r[[2, 3, 4]], 0.01)
    assert np.isclose(r[1] ** 2, 2 * 0.01**2) and np.isclose(r[0] ** 2, r[1] ** 2 + r[4] ** 2)


def _small_truth(**over):
    kw = dict(positions=[[0, 0, 0], [0, 0, 1.0], [0.5, 0, 1.5]], radii=[0.02, 0.01, 0.01], parent=[-1, 0, 1],
              branch_id=[0, 0, 1], branch_order=[0, 0, 1], leaf_positions=[[0.6, 0, 1.6]],
              leaf_wxyz=[[1.0, 0, 0, 0]], leaf_sizes=[0.1], model="guiding", species="x", seed=4,
              parameters={"a": [1, 2]})  # fmt: skip
    kw.update(over)
    return TreeTruth(**kw)


@pytest.mark.parametrize(
    "over, words",
    [
        ({"parent": [-1, 2, 0]}, "parents must come first"),
        ({"parent": [-1, -1, 1]}, "one root"),
        ({"radii": [0.02, 0.0, 0.01]}, "radii"),
        ({"branch_id": [0, 1, 1], "branch_order": [0, 1, 2]}, "constant along a branch"),
        ({"leaf_wxyz": [[2.0, 0, 0, 0]]}, "unit length"),
        ({"positions": [[0, 0, np.nan], [0, 0, 1], [0, 0, 2]]}, "NaN"),
        ({"parameters": {"x": object()}}, "JSON"),
    ],
)
def test_truth_validation(over, words):
    with pytest.raises(ValidationError, match=words):
        _small_truth(**over)


def test_truth_save_load_roundtrip(tmp_path):
    tr = _small_truth()
    assert tr.leaf_node.tolist() == [2]  # nearest node when not given
    path = save_truth(tmp_path / "t.npz", tr)
    back = load_truth(path)
    assert np.array_equal(back.positions, tr.positions) and back.parameters == {"a": [1, 2]}
    assert (back.model, back.species, back.seed) == ("guiding", "x", 4)
    assert np.allclose(leaf_card_corners(back)[0, 2], [0.65, 0.025, 1.6])
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="bad.npz"):
        load_truth(tmp_path / "bad.npz")
    with pytest.raises(InputError, match="no such file"):
        load_truth(tmp_path / "missing.npz")


def test_volumes_contain_what_they_should():
    pts = np.array([[0, 0, 5.0], [0, 0, 4.0], [2.9, 0, 5.0], [0, 0, 8.9], [3.1, 0, 5.0]])
    half = Volume("half_ellipsoid", (0, 0, 5), (3, 3, 4)).contains(pts)
    assert half.tolist() == [True, False, True, True, False]
    assert Volume("ellipsoid", (0, 0, 5), (3, 3, 4)).contains(pts).tolist() == [
        True,
        True,
        True,
        True,
        False,
    ]
    assert Volume("box", (0, 0, 5), (3, 3, 4)).contains(pts)[4] == False  # noqa: E712
    assert Volume("cylinder", (0, 0, 5), (3, 3, 4)).contains(pts).tolist()[:4] == [True] * 4


def test_surface_candidates_are_k_hops_out_and_outermost(rng):
    from scipy.sparse.csgraph import shortest_path

    from arboretum_server.synth.endpoints import surface_candidates

    pts = rng.random((2000, 3)) * 4
    g = yao_graph(pts, 14)
    n = len(pts)
    in_tree = np.zeros(n, bool)
    chain = np.argsort(pts[:, 2])[::200]  # a few tree nodes, with made-up root hops
    in_tree[chain] = True
    root_hops = np.zeros(n, np.int64)
    root_hops[chain] = np.arange(len(chain)) * 3
    cand = surface_candidates(g.neighbours, in_tree, root_hops, 3, 1.0, rng)
    rows = np.repeat(np.arange(n + 1), 14)[: n * 14]
    adj = csr_matrix((np.ones(n * 14), (rows, g.neighbours.ravel())), shape=(n + 1, n + 1)).tolil()
    adj[n, chain] = 1  # a super source feeding the tree
    hops = shortest_path(adj.tocsr(), indices=n, unweighted=True) - 1
    assert len(cand) > 50 and (hops[cand] == 3).all()
    assert set(cand.tolist()) == set(np.flatnonzero(hops == 3).tolist())
    outer = surface_candidates(g.neighbours, in_tree, root_hops, 3, 0.3, np.random.default_rng(0))
    assert len(outer) == int(np.ceil(0.3 * len(cand)))
