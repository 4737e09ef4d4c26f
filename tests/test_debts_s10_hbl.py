"""One walk over an HBL's positions: ``HBL.arrays`` lists them, ``HBL.map_positions`` maps them (the grower
moves a far tree with it), and ``scene_build.hbl_points`` deliberately takes only what is drawn."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.model import HBL, Branch, Level, Lobe

OFFSET = np.array([500000.0, 5400000.0, 12.0])


def _cube(centre, half):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * half + centre
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int32)
    return v, f


def _hbl() -> HBL:
    """Two branches, two lobes (one with a point far outside its hull and the source points), labels."""
    trunk = Branch(np.array([[0.1, 0.2, 0.0], [0.1, 0.2, 1.0], [0.2, 0.2, 2.0]]), np.array([0.1, 0.08, 0.05]))
    side = Branch(np.array([[0.1, 0.2, 1.0], [0.8, 0.3, 1.5]]), np.array([0.04, 0.02]), parent=0,
                  parent_vertex=1, level=Level.SECONDARY)
    v0, f0 = _cube(np.array([0.2, 0.2, 2.2]), 0.3)
    v1, f1 = _cube(np.array([0.9, 0.3, 1.6]), 0.2)
    lobes = (Lobe(np.array([[0.2, 0.2, 2.2], [0.3, 0.1, 2.3]]), v0, f0, np.array([0.25, 0.15, 2.25]), branch=0),
             Lobe(np.array([[9.0, -7.0, 5.0]]), v1, f1, np.array([0.9, 0.3, 1.6]), branch=1))
    pts = np.array([[0.1, 0.2, 0.5], [0.2, 0.2, 2.2], [0.3, 0.1, 2.3]])
    return HBL(np.array([0.1, 0.2, 0.0]), (trunk, side), lobes, pts, np.array([0, 1, 1], np.uint8))


def test_arrays_walks_the_same_fields_in_the_same_order_as_before():
    names = [n for n, _ in _hbl().arrays()]
    assert names == ["root", "points",
                     "branches[0].points", "branches[0].radii", "branches[1].points", "branches[1].radii",
                     "lobes[0].points", "lobes[0].hull_vertices", "lobes[0].centre",
                     "lobes[1].points", "lobes[1].hull_vertices", "lobes[1].centre"]


def test_extent_still_counts_radii_and_every_lobe_point():
    h = _hbl()
    assert h.extent == pytest.approx(9.0)  # lobes[1].points holds x = 9
    big = HBL(h.root, (Branch(np.array([[0, 0, 0], [0, 0, 1.0]]), np.array([3.5, 3.0])),))
    assert big.extent == pytest.approx(3.5)  # a radius beyond every coordinate


def _old_translated(hbl: HBL, off: np.ndarray) -> HBL:
    """The grower's translation before ``map_positions`` (the reference it must match bit for bit)."""
    from dataclasses import replace

    branches = tuple(replace(b, points=b.points + off) for b in hbl.branches)
    lobes = tuple(replace(lb, points=lb.points + off, hull_vertices=lb.hull_vertices + off,
                          centre=lb.centre + off) for lb in hbl.lobes)
    return replace(hbl, root=hbl.root + off, branches=branches, lobes=lobes, points=hbl.points + off)


def test_map_positions_moves_exactly_what_the_old_translation_moved():
    h = _hbl()
    new, old = h.map_positions(lambda a: a - OFFSET), _old_translated(h, -OFFSET)
    assert [n for n, _ in new.arrays()] == [n for n, _ in old.arrays()]
    for (name, a), (_, b) in zip(new.arrays(), old.arrays(), strict=True):
        assert np.array_equal(a, b), name
    assert np.array_equal(new.labels, h.labels)
    assert [(b.parent, b.parent_vertex, b.level) for b in new.branches] == [(-1, -1, Level.MAIN), (0, 1, Level.SECONDARY)]
    assert [lb.branch for lb in new.lobes] == [0, 1]
    assert all(np.array_equal(a.hull_faces, b.hull_faces) for a, b in zip(new.lobes, h.lobes, strict=True))


def test_map_positions_maps_every_position_array_and_no_radius():
    h = _hbl()
    moved = h.map_positions(lambda a: a + OFFSET)
    before, after = dict(h.arrays()), dict(moved.arrays())
    for name, a in ((n, a) for n, a in h.arrays() if not n.endswith(".radii")):
        assert np.array_equal(after[name], a + OFFSET), name
    for name in (n for n in before if n.endswith(".radii")):
        assert np.array_equal(after[name], before[name]), name
    assert moved.map_positions(lambda a: a - OFFSET).lobes[1].points.tolist() == [[9.0, -7.0, 5.0]]


def test_map_positions_result_is_validated_and_read_only():
    from arboretum_library.errors import ValidationError

    moved = _hbl().map_positions(lambda a: a * 2.0)
    assert not moved.root.flags.writeable and not moved.lobes[0].centre.flags.writeable
    with pytest.raises(ValidationError, match=r"^Branch.points: 9 value\(s\) are NaN or infinite"):
        _hbl().map_positions(lambda a: a + np.inf)


def test_grow_tree_far_from_the_origin_still_grows_the_moved_tree():
    """The grower moves a far tree to its growth origin with ``map_positions``: same tree, translated."""
    from arboretum_server.grow.demo import demo_hbl
    from arboretum_server.grow.options import GrowOptions
    from arboretum_server.grow.tree import grow_tree

    near = demo_hbl(np.random.default_rng(3), n_lobes=2)
    near = near.map_positions(lambda a: np.round(a * 2.0**20) / 2.0**20)  # exact when moved by OFFSET
    far = near.map_positions(lambda a: a + OFFSET)
    opts = GrowOptions()
    a = grow_tree(near, opts, np.random.default_rng(0))
    b = grow_tree(far, opts, np.random.default_rng(0))
    assert len(a.positions) == len(b.positions) > len(near.branches[0].points)
    assert np.abs(b.positions - OFFSET - a.positions).max() < 1e-6
    assert np.array_equal(a.parents, b.parents)


def test_hbl_points_frames_only_what_is_drawn():
    """``hbl_points`` differs from ``arrays``: lobe points and centres are not drawn (a lobe point outside
    its hull must not widen the framing), radii are not positions."""
    from arboretum_client.scene_build import hbl_points

    h = _hbl()
    pts = hbl_points(h)
    assert pts.shape == (3 + 2 + 8 + 8 + 3 + 1, 3)
    assert pts.max(axis=0)[0] == pytest.approx(1.1) and pts.min(axis=0)[1] == pytest.approx(-0.1)
    assert not np.isclose(pts, [9.0, -7.0, 5.0]).all(axis=1).any()
