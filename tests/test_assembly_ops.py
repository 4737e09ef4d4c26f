"""Assembly edits, recombination (Algorithm 1 across examples), sketches and assembly_to_hbl."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.assembly import Assembly
from arboretum_library.errors import InputError
from arboretum_library.geometry import axis_angle_matrix, make_transform
from arboretum_library.model import HBL, Branch, Example, Level, Provenance
from arboretum_server.assembly import ops
from arboretum_server.assembly.recombine import RecombineOptions
from arboretum_server.assembly.sketch import recognise
from arboretum_server.assembly.world import assembly_to_hbl, main_world
from factories import make_example

LINE = np.c_[np.zeros(11), np.zeros(11), np.linspace(0, 1.0, 11)]


def straight(id_: str, n_lobes: int = 0, rng=None) -> Example:
    """An example whose main branch is exactly the unit vertical LINE (plus factory lobes)."""
    base = make_example(rng or np.random.default_rng(0), id=id_, n_lobes=n_lobes)
    s = base.structure
    main = Branch(LINE, np.linspace(0.04, 0.01, 11))
    rest = [Branch(b.points, b.radii, 0, min(b.parent_vertex, 10), b.level) for b in s.branches[1:]]
    return Example(id_, HBL(np.zeros(3), [main, *rest], s.lobes), Provenance("t"), base.descriptors)


@pytest.fixture
def lib():
    exs = {e.id: e for e in (straight("a", 2), straight("b", 1), straight("c"))}
    return exs.__getitem__


def test_add_and_transform_recombine_near_main_branches(lib):
    a, out = ops.add_example(Assembly(), lib, "a", np.eye(4))
    assert out.instance == "a#1" and a.merges == ()
    # b's base sits on a's main branch at 0.3 m: b joins a; its first 7 vertices coincide with a's.
    a, out = ops.add_example(a, lib, "b", make_transform(t=[0, 0, 0.3]))
    assert out.merged == ("a#1",)
    (m,) = a.merges
    assert (m.a, m.b) == ("a#1", "b#1")
    assert m.vertex_b == 8 and m.vertex_a == 10  # b[7] is at z = 1.0, the tip of a; b[8] is beyond it
    # moved 2 m away: the link is gone
    a, out = ops.transform_example(a, lib, "b#1", make_transform(t=[2, 0, 0.3]))
    assert a.merges == () and out.merged == ()
    # leaning, with the base near a's main (within 10% of its length): linked again
    R = axis_angle_matrix(np.array([0.0, 1, 0]), np.radians(40))
    a, out = ops.transform_example(a, lib, "b#1", make_transform(R, [0.05, 0, 0.5]))
    (m,) = a.merges
    assert m.vertex_b <= 2 and m.vertex_a == 5


def test_recombination_respects_a_cost_ceiling_and_can_be_disabled(lib):
    a, _ = ops.add_example(Assembly(), lib, "a", np.eye(4))
    a2, _ = ops.add_example(a, lib, "b", make_transform(t=[0, 0, 0.3]), o=RecombineOptions(enabled=False))
    assert a2.merges == ()
    a3, _ = ops.add_example(a, lib, "b", make_transform(t=[0, 0, 0.3]), o=RecombineOptions(max_cost=-1.0))
    assert a3.merges == ()


def test_links_never_form_cycles(lib):
    a, _ = ops.add_example(Assembly(), lib, "a", np.eye(4))
    a, _ = ops.add_example(a, lib, "b", make_transform(t=[0, 0, 0.05]))
    a, _ = ops.add_example(a, lib, "c", make_transform(t=[0, 0, 0.02]))
    parents = {m.b: m.a for m in a.merges}
    assert len(parents) == len(a.merges) <= 2
    for start in parents:
        seen, x = set(), start
        while x in parents:
            assert x not in seen
            seen.add(x)
            x = parents[x]


def test_assembly_to_hbl_merges_and_places(lib):
    a, _ = ops.add_example(Assembly(), lib, "a", np.eye(4))
    a, _ = ops.add_example(a, lib, "b", make_transform(t=[0, 0, 0.3]), scale=1.0)
    a, _ = ops.add_example(a, lib, "c", make_transform(t=[3, 0, 0]), scale=2.0)
    h = assembly_to_hbl(a, lib)
    mains = h.by_level(Level.MAIN)
    assert len(mains) == 3 and len(h.lobes) == 3
    b_main = h.branches[mains[1]]
    assert b_main.parent == mains[0] and b_main.parent_vertex == 10
    assert np.allclose(b_main.points[0], [0, 0, 1.0])  # starts at a's vertex_a
    assert np.allclose(b_main.points[-1], [0, 0, 1.3])
    c_main = h.branches[mains[2]]
    assert c_main.parent == -1 and np.allclose(c_main.points[-1], [3, 0, 2.0])
    assert np.allclose(c_main.radii, 2 * np.linspace(0.04, 0.01, 11))
    # b's secondary branch hung on the merged part of b, so it now hangs on a's main branch
    b_sec = [b for b in h.branches if b.level == Level.SECONDARY and b.parent == mains[0]]
    assert len(b_sec) == 3


def test_transform_lobe_moves_the_lobe_about_its_centre_and_bends_its_branch(lib):
    a, _ = ops.add_example(Assembly(), lib, "a", make_transform(t=[1, 0, 0]))
    before = assembly_to_hbl(a, lib)
    T = make_transform(scale=2.0, t=[0, 0.2, 0])
    a, out = ops.transform_lobe(a, lib, "a#1", 1, T)
    after = assembly_to_hbl(a, lib)
    lb0, lb1 = before.lobes[1], after.lobes[1]
    assert np.allclose(lb1.centre, lb0.centre + [0, 0.2, 0])
    assert np.allclose(lb1.hull_vertices - lb1.centre, 2 * (lb0.hull_vertices - lb0.centre))
    br0, br1 = before.branches[lb0.branch], after.branches[lb1.branch]
    assert np.allclose(br1.points[0], br0.points[0]) and np.allclose(br1.points[-1], br0.points[-1] + [0, 0.2, 0])
    assert np.allclose(after.lobes[0].centre, before.lobes[0].centre)
    with pytest.raises(InputError, match="lobe 5 does not exist"):
        ops.transform_lobe(a, lib, "a#1", 5, T)
    with pytest.raises(InputError, match="uniform scale"):
        ops.transform_lobe(a, lib, "a#1", 0, np.diag([1.0, 2.0, 1.0, 1.0]))


def test_delete_removes_placement_and_links(lib):
    a, _ = ops.add_example(Assembly(), lib, "a", np.eye(4))
    a, _ = ops.add_example(a, lib, "b", make_transform(t=[0, 0, 0.3]))
    a, out = ops.delete_example(a, "a#1")
    assert [p.instance for p in a.placements] == ["b#1"] and a.merges == ()
    with pytest.raises(InputError, match="no placement 'a#1'"):
        ops.delete_example(a, "a#1")


def test_instances_are_unique_and_named(lib):
    a, o1 = ops.add_example(Assembly(), lib, "c", make_transform(t=[5, 0, 0]))
    a, o2 = ops.add_example(a, lib, "c", make_transform(t=[9, 0, 0]))
    assert (o1.instance, o2.instance) == ("c#1", "c#2")
    with pytest.raises(InputError, match="already exists"):
        ops.add_example(a, lib, "c", np.eye(4), instance="c#1")
    with pytest.raises(InputError, match="instance name"):
        ops.add_example(a, lib, "c", np.eye(4), instance="bad name!")
    with pytest.raises(InputError, match="rigid"):
        ops.add_example(a, lib, "c", np.diag([2.0, 1, 1, 1]))


def circle(c, r, n=24, z=0.0):
    t = np.linspace(0, 2 * np.pi * 0.95, n)
    return np.c_[c[0] + r * np.cos(t), c[1] + r * np.sin(t), np.full(n, c[2] + z)]


def test_strokes_are_recognised():
    assert recognise(LINE) == "branch"
    assert recognise(circle([0, 0, 1], 0.2)) == "lobe"
    zig = np.c_[np.tile([0.0, 0.3], 6), np.tile([0.0, 0.05], 6), np.linspace(0, 0.1, 12)]
    assert recognise(zig) == "lobe"  # a scribble
    with pytest.raises(InputError, match="no length"):
        recognise(np.zeros((4, 3)))


def test_sketch_builds_a_placed_example(lib):
    trunk = LINE * 2 + [1, 1, 0]
    side = np.c_[np.linspace(0, 0.6, 6), np.zeros(6), np.linspace(1.0, 1.4, 6)] + [1, 1, 0]
    strokes = [side, trunk[::-1], circle([1.7, 1, 1.5], 0.15), circle([1, 1, 2.2], 0.2)]
    a, out = ops.sketch(Assembly(), lib, strokes)
    assert out.kinds == ("branch", "branch", "lobe", "lobe")
    ex = a.sketches[0]
    assert ex.id == "sketch-0001" and out.instance == "sketch-0001#1" and "sketch" in ex.tags
    s = ex.structure
    assert [b.level for b in s.branches] == [Level.MAIN, Level.SECONDARY, Level.SECONDARY]
    assert np.allclose(main_world(a.placements[0], ex)[0], [1, 1, 0])  # grown from the lower end
    assert [lb.branch for lb in s.lobes] == [1, 2]  # the side branch feeds the first lobe; a new one the other
    h = assembly_to_hbl(a, lib)
    assert np.allclose(h.lobes[1].centre, np.mean(strokes[3], axis=0))
    with pytest.raises(InputError, match="at least one branch stroke"):
        ops.sketch(Assembly(), lib, [circle([0, 0, 1], 0.2)])
