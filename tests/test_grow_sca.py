"""Space colonization in lobes (VRTree Eq. 2): containment, determinism, density and Eq. 2's terms."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.model import HBL, Level
from arboretum_server.grow.demo import demo_hbl
from arboretum_server.grow.options import GrowOptions
from arboretum_server.grow.radii import depths
from arboretum_server.grow.tree import grow_tree
from factories import make_hbl
from test_grow_hulls import winding_number


@pytest.fixture(scope="module")
def hbl() -> HBL:
    return make_hbl(np.random.default_rng(7), n_main=3, n_lobes=6)


@pytest.fixture(scope="module")
def tree(hbl):
    return grow_tree(hbl, GrowOptions(), np.random.default_rng(0))


def test_twigs_grow_in_every_lobe(hbl, tree):
    per_lobe = np.bincount(tree.lobe[tree.lobe >= 0], minlength=len(hbl.lobes))
    assert (per_lobe > 30).all(), per_lobe
    assert tree.twig_count == int((tree.lobe >= 0).sum())
    assert (tree.levels[tree.lobe >= 0] == Level.TWIG).all()


def test_twigs_stay_inside_their_hull_or_within_one_step(hbl, tree):
    """A twig node outside its hull is a child of a node inside it, one step D away (so <= D out)."""
    twig = np.flatnonzero(tree.lobe >= 0)
    inside = np.zeros(len(tree.positions), bool)
    for i, lb in enumerate(hbl.lobes):
        sel = twig[tree.lobe[twig] == i]
        inside[sel] = winding_number(lb.hull_vertices, lb.hull_faces, tree.positions[sel]) > 0.5
    out = twig[~inside[twig]]
    assert inside[twig].mean() > 0.9
    par = tree.parents[out]
    assert inside[par].all() or (tree.lobe[par[~inside[par]]] < 0).all()  # or the bud (inside here)
    edge = np.linalg.norm(tree.positions[out] - tree.positions[par], axis=1)
    assert (edge <= tree.step * (1 + 1e-9)).all()


def test_every_twig_reaches_the_trunk_root(tree):
    assert tree.parents[0] == -1 and (tree.parents[1:] >= 0).all()
    assert (tree.parents[1:] < np.arange(1, len(tree.parents))).all()
    assert depths(tree.parents).max() < len(tree.parents)


def test_twig_edges_are_one_growth_step(tree):
    twig = np.flatnonzero(tree.lobe >= 0)
    edge = np.linalg.norm(tree.positions[twig] - tree.positions[tree.parents[twig]], axis=1)
    assert np.allclose(edge, tree.step)


def test_same_seed_same_tree_other_seed_other_tree(hbl, tree):
    again = grow_tree(hbl, GrowOptions(), np.random.default_rng(0))
    assert again.positions.tobytes() == tree.positions.tobytes()
    assert again.leaves.centres.tobytes() == tree.leaves.centres.tobytes()
    other = grow_tree(hbl, GrowOptions(), np.random.default_rng(1))
    assert other.positions.shape != tree.positions.shape or not np.allclose(other.positions, tree.positions)


def test_global_and_per_lobe_density(hbl, tree):
    dense = grow_tree(hbl, GrowOptions(density=2.5), np.random.default_rng(0))
    assert dense.twig_count > 1.3 * tree.twig_count
    off = grow_tree(hbl, GrowOptions(lobe_density={2: 0.0}), np.random.default_rng(0))
    counts = np.bincount(off.lobe[off.lobe >= 0], minlength=len(hbl.lobes))
    assert counts[2] <= 1 and (np.delete(counts, 2) > 30).all()


def test_gravity_alpha_bends_twigs_down(hbl):
    """Eq. 2: raising α lowers the mean vertical direction of twig segments."""
    def mean_dz(alpha: float) -> float:
        t = grow_tree(hbl, GrowOptions(alpha=alpha), np.random.default_rng(0))
        twig = np.flatnonzero(t.lobe >= 0)
        d = t.positions[twig] - t.positions[t.parents[twig]]
        return float((d[:, 2] / np.linalg.norm(d, axis=1)).mean())

    assert mean_dz(3.0) < mean_dz(1.6) < mean_dz(0.0)


def test_ellipsoid_lobes_are_filled(rng):
    """Twigs reach well into the lobe: their spread is a large part of the hull's extent."""
    h = demo_hbl(np.random.default_rng(5), n_lobes=4)
    t = grow_tree(h, GrowOptions(), np.random.default_rng(0))
    for i, lb in enumerate(h.lobes):
        pts = t.positions[t.lobe == i]
        ext = np.ptp(lb.hull_vertices, axis=0)
        assert (np.ptp(pts, axis=0) > 0.6 * ext).all(), (i, np.ptp(pts, axis=0), ext)


def test_bud_outside_its_hull_approaches_it():
    """A secondary branch ending outside its lobe: an approach twig grows in, then the lobe fills."""
    h = demo_hbl(np.random.default_rng(5), n_lobes=2)
    lobes = [dataclasses.replace(lb, hull_vertices=lb.hull_vertices + [0.0, 0.0, 1.2],
                                 centre=lb.centre + [0.0, 0.0, 1.2]) for lb in h.lobes]
    h2 = HBL(h.root, h.branches, lobes)
    t = grow_tree(h2, GrowOptions(), np.random.default_rng(0))
    for i, lb in enumerate(lobes):
        pts = t.positions[t.lobe == i]
        assert (winding_number(lb.hull_vertices, lb.hull_faces, pts) > 0.5).sum() > 30


def test_bad_options_are_input_errors():
    with pytest.raises(InputError, match="step"):
        GrowOptions(step=-1.0)
    with pytest.raises(InputError, match="lobe_density"):
        GrowOptions(lobe_density={0: -1.0})


def test_unlimited_influence_fills_lobes_too(hbl, tree):
    """d_i = None (every live point pulls its nearest node) reaches more points: more twigs."""
    t = grow_tree(hbl, GrowOptions(influence=None, max_iterations=120), np.random.default_rng(0))
    assert tree.twig_count < t.twig_count < 6 * tree.twig_count
    per_lobe = np.bincount(t.lobe[t.lobe >= 0], minlength=len(hbl.lobes))
    assert (per_lobe > 30).all()


def _torus(centre: np.ndarray, major: float, minor: float, n: int = 24, m: int = 12):
    """A closed torus mesh round the vertical axis through ``centre``: (vertices, outward faces)."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n, endpoint=False), np.linspace(0, 2 * np.pi, m, endpoint=False),
                       indexing="ij")
    ring = major + minor * np.cos(v)
    verts = np.stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(v)], axis=-1).reshape(-1, 3) + centre
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    a, b = i * m + j, ((i + 1) % n) * m + j
    c, d = ((i + 1) % n) * m + (j + 1) % m, i * m + (j + 1) % m
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return verts, faces.astype(np.int32)


def test_lobe_wrapped_round_its_bud_fills():
    """A lobe carved round the trunk holds its bud in the hole: whole-lobe pulls cancel there, so the
    approach heads for the nearest point and twigs that would cross the hole turn back inside."""
    h = demo_hbl(np.random.default_rng(5), n_lobes=2)
    lb = h.lobes[0]
    bud = h.branches[lb.branch].points[-1]
    verts, faces = _torus(bud, 0.45, 0.2)
    assert winding_number(verts, faces, np.array([bud, bud + [0.45, 0, 0]])).round(3).tolist() == [0.0, 1.0]
    ring = dataclasses.replace(lb, hull_vertices=verts, hull_faces=faces, centre=bud.copy())
    h2 = HBL(h.root, h.branches, (ring, *h.lobes[1:]))
    t = grow_tree(h2, GrowOptions(), np.random.default_rng(0))
    pts = t.positions[t.lobe == 0]
    inside = winding_number(verts, faces, pts) > 0.5
    assert inside.sum() > 150, inside.sum()
    angle = np.arctan2(pts[inside, 1] - bud[1], pts[inside, 0] - bud[0])
    sector = ((angle + np.pi) / (np.pi / 4)).astype(int) % 8
    assert (np.bincount(sector, minlength=8) > 10).all()  # twigs go all round the ring, not only where they entered
