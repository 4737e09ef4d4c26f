"""HBL records: validation names the field; arrays are copied and frozen."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.assembly import Assembly, MergeLink, Placement
from arboretum_library.descriptors import describe
from arboretum_library.errors import ValidationError
from arboretum_library.geometry import axis_angle_matrix, make_transform
from arboretum_library.model import HBL, Branch, Example, Level, Lobe, Provenance

TETRA_V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]
TETRA_F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def trunk(n: int = 5) -> Branch:
    return Branch(np.c_[np.zeros(n), np.zeros(n), np.linspace(0, 1, n)], np.linspace(0.05, 0.01, n))


def side(parent: int = 0, vertex: int = 2) -> Branch:
    return Branch([[0, 0, 0.5], [0.3, 0, 0.7]], [0.01, 0.005], parent, vertex, Level.SECONDARY)


def test_branch_arrays_are_copied_and_read_only():
    pts = np.c_[np.zeros(3), np.zeros(3), [0, 1, 2.0]]
    b = Branch(pts, [0.1, 0.1, 0.1])
    pts[0, 0] = 99
    assert b.points[0, 0] == 0
    with pytest.raises(ValueError):
        b.points[0, 0] = 1
    assert b.length == pytest.approx(2.0)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"points": [[0, 0, 0]], "radii": [1]}, "Branch.points"),
        ({"points": [[0, 0], [1, 1]], "radii": [1, 1]}, "Branch.points"),
        ({"points": [[0, 0, 0], [0, 0, np.nan]], "radii": [1, 1]}, "Branch.points"),
        ({"points": [[0, 0, 0], [0, 0, 1]], "radii": [1]}, "Branch.radii"),
        ({"points": [[0, 0, 0], [0, 0, 1]], "radii": [1, 0]}, "Branch.radii"),
        ({"points": [[0, 0, 0], [0, 0, 1]], "radii": [1, 1], "parent": 0}, "Branch.parent_vertex"),
    ],
)
def test_branch_validation_names_the_field(kwargs, field):
    with pytest.raises(ValidationError, match=field):
        Branch(**kwargs)


def test_lobe_validation():
    Lobe(np.zeros((0, 3)), TETRA_V, TETRA_F, [0.2, 0.2, 0.2])
    with pytest.raises(ValidationError, match="Lobe.hull_faces"):
        Lobe(np.zeros((0, 3)), TETRA_V, [[0, 1, 4]] * 4, [0, 0, 0])
    with pytest.raises(ValidationError, match="Lobe.hull_faces"):
        Lobe(np.zeros((0, 3)), TETRA_V[:3], TETRA_F[:1], [0, 0, 0])
    with pytest.raises(ValidationError, match="Lobe.centre"):
        Lobe(np.zeros((0, 3)), TETRA_V, TETRA_F, [0, 0])


def test_hbl_topology_checks():
    lobe = Lobe(np.zeros((2, 3)), TETRA_V, TETRA_F, [0.3, 0, 0.7], branch=1)
    h = HBL([0, 0, 0], [trunk(), side()], [lobe], np.zeros((4, 3)), [0, 1, 1, 0])
    assert h.by_level(Level.SECONDARY) == [1]
    assert h.height == pytest.approx(1.0)
    with pytest.raises(ValidationError, match="must come before"):
        HBL([0, 0, 0], [side(parent=1), trunk()])
    with pytest.raises(ValidationError, match="parent_vertex"):
        HBL([0, 0, 0], [trunk(3), side(vertex=3)])
    with pytest.raises(ValidationError, match="HBL.lobes\\[0\\].branch"):
        HBL([0, 0, 0], [trunk()], [lobe])
    with pytest.raises(ValidationError, match="HBL.labels"):
        HBL([0, 0, 0], [trunk()], points=np.zeros((2, 3)), labels=[0, 2])
    with pytest.raises(ValidationError, match="cannot grow from"):
        HBL([0, 0, 0], [trunk(), side(), Branch([[0, 0, 0], [0, 0, 1]], [1, 1], 1, 0, Level.MAIN)])


def test_example_needs_one_main_branch_first():
    h = HBL([0, 0, 0], [trunk(), side()])
    d = describe(h)
    ex = Example("a_1", h, Provenance("x.xyz"), d, ("Curved", "dense", "curved"))
    assert ex.tags == ("curved", "dense")
    with pytest.raises(ValidationError, match="Example.id"):
        Example("bad id!", h, Provenance("x"), d)
    two = HBL([0, 0, 0], [trunk(), Branch([[1, 0, 0], [1, 0, 1]], [1, 1])])
    with pytest.raises(ValidationError, match="exactly one MAIN"):
        Example("b", two, Provenance("x"), d)


def test_placement_and_assembly_checks():
    T = make_transform(axis_angle_matrix([0, 0, 1], 0.7), [1, 2, 0])
    p = Placement("i1", "ex", T, 1.5)
    q = Placement("i2", "ex", np.eye(4))
    a = Assembly((p, q), merges=(MergeLink("i1", "i2", 3, 1),))
    assert len(a.placements) == 2
    with pytest.raises(ValidationError, match="rigid"):
        Placement("i3", "ex", make_transform(scale=2.0))
    with pytest.raises(ValidationError, match="scale"):
        Placement("i3", "ex", np.eye(4), scale=0.0)
    with pytest.raises(ValidationError, match="unique"):
        Assembly((p, p))
    with pytest.raises(ValidationError, match="merges"):
        Assembly((p,), merges=(MergeLink("i1", "nope", 0, 0),))
