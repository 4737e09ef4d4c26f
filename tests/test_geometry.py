"""Geometry helpers, with property tests for the frame conversions and transforms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from arboretum_library.geometry import (
    apply_transform,
    axis_angle_matrix,
    make_transform,
    point_polyline_distance,
    polyline_lengths,
    resample_polyline,
    yup_to_zup,
    zup_to_yup,
)

finite = st.floats(-1e3, 1e3, allow_nan=False)
clouds = arrays(np.float64, st.tuples(st.integers(1, 20), st.just(3)), elements=finite)


@given(clouds)
def test_frame_conversion_round_trips_and_keeps_handedness(p):
    assert np.array_equal(yup_to_zup(zup_to_yup(p)), p)
    # Z up becomes Y up, and a right-handed basis stays right-handed.
    e = zup_to_yup(np.eye(3))
    assert np.allclose(e[2], [0, 1, 0])
    assert np.linalg.det(e) == pytest.approx(1.0)


@settings(max_examples=50)
@given(arrays(np.float64, 3, elements=st.floats(-1, 1)).filter(lambda a: np.linalg.norm(a) > 1e-3), st.floats(-6.3, 6.3))
def test_axis_angle_is_a_rotation(axis, angle):
    R = axis_angle_matrix(axis, angle)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(R @ axis, axis, atol=1e-9)


def test_rotation_direction_is_right_handed():
    R = axis_angle_matrix([0, 0, 1], np.pi / 2)
    assert np.allclose(R @ [1, 0, 0], [0, 1, 0])


def test_transform_applies_scale_rotation_translation():
    T = make_transform(axis_angle_matrix([0, 0, 1], np.pi / 2), [1, 0, 0], scale=2.0)
    assert np.allclose(apply_transform(T, [[1, 0, 0]]), [[1, 2, 0]])


def test_resample_keeps_ends_and_spacing():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0.0]])
    r = resample_polyline(p, 7)
    assert np.allclose(r[0], p[0]) and np.allclose(r[-1], p[-1])
    assert np.allclose(np.diff(polyline_lengths(r)), 0.5)


def test_point_polyline_distance():
    line = np.array([[0, 0, 0], [1, 0, 0.0]])
    d = point_polyline_distance([[0.5, 1, 0], [2, 0, 0], [-1, 0, 1]], line)
    assert np.allclose(d, [1, 1, np.sqrt(2)])
