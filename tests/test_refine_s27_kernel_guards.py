"""The compiled kernels check no array bounds: their wrappers refuse face indices that would make them read
memory they do not own (session 27, helper-189's direct probe of the wrappers)."""

import numpy as np
import pytest

from arboretum_server.decompose import hullpack, tetloops

TET = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
"""A closed tetrahedron's outward faces."""


def test_closed_manifold_refuses_negative_indices():
    # a tetrahedron with vertex 2 written as -2: numba would wrap it to the last vertex
    assert tetloops.is_closed_manifold(TET) is True
    assert tetloops.is_closed_manifold(np.where(TET == 2, -2, TET)) is False


def test_pack_hull_refuses_faces_past_the_vertices():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert hullpack.pack_hull(v, TET).faces.shape == (4, 3)
    with pytest.raises(ValueError, match="face indices 0..4 for 4 vertices"):
        hullpack.pack_hull(v, np.where(TET == 3, 4, TET))
    with pytest.raises(ValueError, match="face indices -1..2"):
        hullpack.pack_hull(v, np.where(TET == 3, -1, TET))
