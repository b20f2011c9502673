"""SE(2) helpers: group laws and frame conventions, as properties over random poses."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mbicp_viz.core import Pose2, pose_error, relative, wrap_angle

coord = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False, exclude_max=True)
poses = st.builds(Pose2, coord, coord, angle)
points = st.lists(st.tuples(coord, coord), min_size=1, max_size=10).map(np.array)


def close(a: Pose2, b: Pose2, tol=1e-9):
    return (
        abs(a.x - b.x) < tol and abs(a.y - b.y) < tol and abs(wrap_angle(a.theta - b.theta)) < tol
    )


@given(poses, poses, poses)
def test_composition_is_associative(a, b, c):
    assert close((a @ b) @ c, a @ (b @ c), 1e-7)


@given(poses)
def test_inverse_cancels(a):
    assert close(a @ a.inverse(), Pose2())
    assert close(a.inverse() @ a, Pose2())


@given(poses, poses)
def test_relative_round_trip(a, b):
    # evo's check: a (+) (a^-1 (+) b) == b
    assert close(a @ relative(a, b), b, 1e-7)


@given(poses, poses, points)
def test_apply_follows_composition(a, b, p):
    np.testing.assert_allclose((a @ b).apply(p), a.apply(b.apply(p)), atol=1e-7)


@given(poses, points)
def test_apply_is_rigid(a, p):
    q = a.apply(p)
    np.testing.assert_allclose(
        np.linalg.norm(q - q[:1], axis=1), np.linalg.norm(p - p[:1], axis=1), atol=1e-8
    )


def test_frame_convention_maps_child_into_parent():
    # The object frame sits 1 m ahead of the reference, turned left by 90 degrees: a point 1 m
    # ahead of the object sensor is at (1, 1) in the reference frame.
    T_ref_obj = Pose2(1.0, 0.0, np.pi / 2)
    np.testing.assert_allclose(T_ref_obj.apply(np.array([[1.0, 0.0]])), [[1.0, 1.0]], atol=1e-12)


@given(poses)
def test_pose_error_of_self_is_zero(a):
    t, r = pose_error(a, a)
    assert t < 1e-9 and r < 1e-9


@given(st.floats(-1e3, 1e3, allow_nan=False))
def test_wrap_angle_range(t):
    w = wrap_angle(t)
    assert -np.pi <= w < np.pi
    assert abs(np.sin(w) - np.sin(t)) < 1e-6 and abs(np.cos(w) - np.cos(t)) < 1e-6
