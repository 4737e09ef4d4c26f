"""The harmonic particle species model: equation 1 terms, seeds, radii, leaves, presets, sampling."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arboretum_library.errors import InputError
from arboretum_library.geometry import quat_to_matrix
from arboretum_library.truth import TreeTruth, branch_polylines
from arboretum_server.synth import quat
from arboretum_server.synth.harmonic import SPECIES, grow_species, silhouette_stats
from arboretum_server.synth.harmonic_presets import sample_species
from arboretum_server.synth.species import LeafParams, LevelParams, SpeciesParams, species_from_dict

ARRAYS = ("positions", "radii", "parent", "branch_id", "branch_order",
          "leaf_positions", "leaf_wxyz", "leaf_sizes", "leaf_node")


def _two_levels(span=(0.0, 0.0, 0.0, 0.0), wander=0.0, harmonic=0.0, angle=90.0) -> SpeciesParams:
    """A straight vertical trunk with one node at age 5 carrying one level-1 branch (no variation)."""
    trunk = LevelParams(angle=0.0, length=10, node_spacing=100, node_start=5)
    branch = LevelParams(angle=angle, length=20, span_angle=span, wander_spacing=(3, 0, 0, 0),
                         wander_amplitude=(wander, 0, 0, 0), harmonic_frequency=(0.5, 0, 0, 0),
                         harmonic_amplitude=(harmonic, 0, 0, 0))
    return SpeciesParams(max_age=30, segment_size=0.1, levels=(trunk, branch), variation=0.0, elongation=0.0)


def _branch_dirs(t: TreeTruth, order: int = 1) -> np.ndarray:
    """Unit internode directions (K, 3) of the first branch of ``order``, fork first."""
    chain = next(c for c in branch_polylines(t) if t.branch_order[c[-1]] == order)
    d = np.diff(t.positions[chain], axis=0)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_positive_span_angle_curves_the_branch_upward():
    up = _branch_dirs(grow_species(_two_levels(span=(3.0, 0, 0, 0)), 1))
    assert len(up) == 20
    assert np.all(np.diff(up[:, 2]) > 0.02)
    assert np.degrees(np.arcsin(up[:, 2])) == pytest.approx(3.0 * np.arange(20), abs=1e-9)
    down = _branch_dirs(grow_species(_two_levels(span=(-3.0, 0, 0, 0)), 1))
    assert np.all(np.diff(down[:, 2]) < -0.02)


def test_span_sections_switch_at_their_spacing():
    lv = dataclasses.replace(_two_levels().levels[1], span_spacing=(0, 10, 1000, 1000),
                             span_angle=(2.0, -4.0, 0.0, 0.0))
    sp = dataclasses.replace(_two_levels(), levels=(_two_levels().levels[0], lv))
    dz = np.diff(_branch_dirs(grow_species(sp, 1))[:, 2])
    assert np.all(dz[:9] > 0) and np.all(dz[10:] < 0)


def test_zero_span_wander_and_harmonic_give_straight_branches():
    t = grow_species(_two_levels(angle=60.0), 4)
    for order in (0, 1):
        d = _branch_dirs(t, order)
        assert np.abs(d - d[0]).max() < 1e-12
    assert _branch_dirs(t, 0)[0] == pytest.approx([0, 0, 1])
    assert np.degrees(np.arccos(_branch_dirs(t, 1)[0, 2])) == pytest.approx(60.0)


def test_harmonic_term_waves_the_branch():
    d = _branch_dirs(grow_species(_two_levels(harmonic=6.0), 1))
    side = np.cross(d[:-1], d[1:])[:, 2]  # turning left or right about Z
    assert np.sum(np.diff(np.sign(side[np.abs(side) > 1e-6])) != 0) >= 2


def test_wander_changes_with_the_seed_and_only_then():
    straight = [grow_species(_two_levels(), s).positions for s in (1, 2)]
    assert np.abs(straight[0][:, 2] - straight[1][:, 2]).max() < 1e-12
    wand = [_branch_dirs(grow_species(_two_levels(wander=8.0), s)) for s in (1, 2)]
    assert np.abs(wand[0] - wand[1]).max() > 0.05
    assert np.degrees(np.arccos(np.clip((wand[0][:-1] * wand[0][1:]).sum(1), -1, 1))).max() > 3


@pytest.mark.parametrize("name", ["pine", "oak"])
def test_same_seed_same_tree_and_new_seed_new_individual(name):
    a, b, c = grow_species(name, 11), grow_species(name, 11), grow_species(name, 12)
    for field in ARRAYS:
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert a.node_count != c.node_count or not np.array_equal(a.positions, c.positions)
    assert abs(silhouette_stats(a)["height"] - silhouette_stats(c)["height"]) > 0.01


@pytest.mark.parametrize("name", sorted(SPECIES))
def test_every_preset_grows_a_sane_valid_tree(name):
    t = grow_species(name, 3)
    st = silhouette_stats(t)
    assert t.model == "harmonic" and t.species == name and t.seed == 3
    assert 3.0 < st["height"] < 35.0 and 1.0 < st["width"] < 25.0
    assert 300 < t.node_count < 60_000 and t.leaf_count > 50
    assert 0.03 < t.radii[0] < 0.6 and t.radii.min() > 0
    assert t.branch_order.max() == len(SPECIES[name].levels) - 1
    assert np.all(t.radii[1:] <= t.radii[t.parent[1:]] + 1e-12)  # no child thicker than its parent
    assert species_from_dict(t.parameters) == SPECIES[name]


def _mean_stats(name: str) -> dict[str, float]:
    stats = [silhouette_stats(grow_species(name, s)) for s in (1, 2, 3)]
    return {k: float(np.mean([s[k] for s in stats])) for k in stats[0]}


def test_presets_differ_in_silhouette_as_the_species_do():
    s = {n: _mean_stats(n) for n in SPECIES}
    hw = {n: v["height_width"] for n, v in s.items()}
    assert hw["pine"] > 2.0 > 1.0 > hw["oak"] and hw["walnut"] < 1.3
    assert hw["pine"] > max(hw["oak"], hw["apple"], hw["cherry"], hw["walnut"])
    assert hw["eucalyptus"] > hw["birch"] > hw["oak"]
    assert hw["ginkgo"] > hw["apple"]
    assert s["eucalyptus"]["crown_base"] > 0.45 > max(s[n]["crown_base"] for n in SPECIES if n != "eucalyptus")
    assert s["pine"]["crown_base"] < min(s[n]["crown_base"] for n in ("apple", "oak", "walnut", "birch"))
    assert s["pine"]["top_width"] < 0.5 < min(s[n]["top_width"] for n in ("oak", "walnut", "apple", "cherry"))
    assert s["eucalyptus"]["height"] > 2 * s["apple"]["height"]
    assert s["oak"]["width"] > s["pine"]["width"]


def test_radii_follow_the_pipe_model_at_forks():
    t = grow_species("walnut", 5)
    e = SPECIES["walnut"].pipe_exponent
    kids = np.bincount(t.parent[1:], minlength=t.node_count)
    fork = np.flatnonzero(kids >= 2)
    assert len(fork) > 20
    acc = np.zeros(t.node_count)
    np.add.at(acc, t.parent[1:], t.radii[1:] ** e)
    assert np.all(t.radii[fork] >= acc[fork] ** (1 / e) - 1e-12)
    assert t.radii[0] > 10 * np.median(t.radii)


def test_leaves_follow_leaf_spacing_probability_and_scale():
    leaf = LeafParams(spacing=2, probability=1.0, scale=0.1, angle_min=(0, 0, 0), angle_max=(0, 0, 0))
    sp = SpeciesParams(max_age=10, segment_size=0.1, variation=0.0, elongation=0.0,
                       levels=(LevelParams(angle=0.0, length=10, leaf=leaf),))
    t = grow_species(sp, 0)
    assert t.leaf_count == 4 and np.array_equal(t.leaf_node, [2, 4, 6, 8])
    assert np.allclose(t.leaf_sizes, 0.1)
    R = np.stack([quat_to_matrix(q) for q in t.leaf_wxyz])
    assert np.allclose(R[:, :, 0], [0, 0, 1])  # blade along the (vertical) shoot
    assert np.allclose(t.leaf_positions - t.positions[t.leaf_node], [0, 0, 0.05])
    pine = grow_species("pine", 1)
    assert set(np.unique(pine.branch_order[pine.leaf_node])) == {2}


def test_younger_trees_are_smaller():
    young, old = grow_species("oak", 2, steps=25), grow_species("oak", 2)
    assert young.node_count < old.node_count / 2
    assert silhouette_stats(young)["height"] < silhouette_stats(old)["height"]


def test_sampled_species_grow_valid_and_diverse_trees():
    rng = np.random.default_rng(2024)
    stats = []
    for k in range(10):
        sp = sample_species(rng)
        t = grow_species(sp, k)
        assert t.node_count >= 20 and t.leaf_count > 0 and t.species == "custom"
        assert np.all(t.radii[1:] <= t.radii[t.parent[1:]] + 1e-12)
        stats.append(silhouette_stats(t)["height_width"])
    assert max(stats) > 2 * min(stats)
    assert sample_species(np.random.default_rng(5)) == sample_species(np.random.default_rng(5))


def test_user_errors_are_input_errors():
    with pytest.raises(InputError, match="unknown harmonic species 'maple'"):
        grow_species("maple", 1)
    with pytest.raises(InputError, match="steps"):
        grow_species("oak", 1, steps=0)
    with pytest.raises(InputError, match="seed"):
        grow_species("oak", -1)
    with pytest.raises(InputError, match=r"levels\[0\].probability"):
        SpeciesParams(levels=(LevelParams(probability=1.5),))


def test_level_frame_keeps_local_x_horizontal_and_positive_pitch_up():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    q = quat.level_frame(d, np.zeros(50))
    assert np.allclose(quat.rotate(q, quat.EZ), d)
    assert np.allclose(quat.rotate(q, quat.EX)[:, 2], 0)
    pitched = quat.rotate(quat.mul(q, quat.axis_angle(quat.EX, np.full(50, 0.1))), quat.EZ)
    assert np.all(pitched[:, 2] > d[:, 2] - 1e-12)
    m = quat_to_matrix(q[7])
    assert np.allclose(quat.from_matrix(m), q[7])


def test_every_internode_keeps_growing_in_length_and_girth():
    young, old = grow_species("walnut", 4, steps=30), grow_species("walnut", 4, steps=40)
    n = young.node_count
    assert np.array_equal(young.parent, old.parent[:n]) and np.array_equal(young.branch_id, old.branch_id[:n])
    seg = [np.linalg.norm(t.positions[1:n] - t.positions[t.parent[1:n]], axis=1) for t in (young, old)]
    assert np.all(seg[1] >= seg[0] - 1e-12) and np.mean(seg[1] > seg[0] + 1e-9) > 0.9
    assert np.all(old.radii[:n] > young.radii[:n])


def test_broad_leaves_face_up_and_keep_their_scale():
    t = grow_species("oak", 2)
    R = np.stack([quat_to_matrix(q) for q in t.leaf_wxyz[:300]])
    face_up = R[:, 2, 2]  # world Z of each card normal
    assert np.mean(face_up) > 0.4 and np.mean(face_up > 0) > 0.8
    v = SPECIES["oak"].variation  # leaf scale 0.1, varied per tree and again per leaf
    assert np.all((t.leaf_sizes > 0.1 * (1 - v) ** 2) & (t.leaf_sizes < 0.1 * (1 + v) ** 2))
    assert np.std(t.leaf_sizes) > 0.001


def test_equation_1_matches_a_per_bud_matrix_reference():
    from arboretum_library.geometry import axis_angle_matrix
    from arboretum_server.synth.harmonic_growth import _Buds, _Tables, _turn

    lv = LevelParams(span_spacing=(0, 5, 12, 20), span_angle=(2.0, -1.0, 3.0, -4.0),
                     harmonic_frequency=(0.3, 0.7, 0.2, 1.1), harmonic_amplitude=(2.0, 1.5, 1.0, 0.5))
    sp = SpeciesParams(levels=(LevelParams(), lv))
    rng = np.random.default_rng(3)
    m = 40
    b = _Buds(q=quat.normalize(rng.normal(size=(m, 4))), last=np.zeros(m, np.int64),
              level=rng.integers(0, 2, m), branch=np.zeros(m, np.int64), age=rng.integers(0, 30, m),
              term=np.full(m, 99), phase=rng.uniform(0, 6.3, (m, 4)))
    got = _turn(b, _Tables(sp), rng)
    ex, ey = np.eye(3)[0], np.eye(3)[1]
    for i in range(m):
        p = sp.levels[b.level[i]]
        k = max(j for j, s in enumerate(p.span_spacing) if s <= b.age[i])
        ref = quat_to_matrix(b.q[i]) @ axis_angle_matrix(ex, np.radians(p.span_angle[k]))
        for j in range(4):
            h = np.sin(b.age[i] * p.harmonic_frequency[j] + b.phase[i, j]) * np.radians(p.harmonic_amplitude[j])
            ref = ref @ axis_angle_matrix(ey if j % 2 == 0 else ex, h)
        assert np.allclose(quat_to_matrix(got[i]), ref, atol=1e-12)
