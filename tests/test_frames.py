"""Frame conversions: round trips and hand-worked cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl import frames as F

rng = np.random.default_rng(0)
VECTORS = rng.normal(size=(20, 3))
QUATS = F.quat_normalize(rng.normal(size=(20, 4)))


def test_world_and_body_vector_conversions_round_trip():
    np.testing.assert_array_equal(F.ned_to_enu(F.enu_to_ned(VECTORS)), VECTORS)
    np.testing.assert_array_equal(F.frd_to_flu(F.flu_to_frd(VECTORS)), VECTORS)
    np.testing.assert_allclose(
        F.quat_ned_frd_to_enu_flu(F.quat_enu_flu_to_ned_frd(QUATS)), QUATS, atol=1e-15
    )


def test_hand_worked_vectors():
    np.testing.assert_array_equal(
        F.enu_to_ned([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0]
    )  # east=1, north=2, up=3
    np.testing.assert_array_equal(F.flu_to_frd([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0])


def test_nose_east_in_enu_is_yaw_90_degrees_in_ned():
    q_enu = F.quat_from_euler(0.0, 0.0, 0.0)  # yaw 0 in ENU: nose along +x = East
    roll, pitch, yaw = F.euler_from_quat(F.quat_enu_flu_to_ned_frd(q_enu))
    assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert yaw == pytest.approx(math.pi / 2)
    assert F.yaw_enu_to_ned(0.0) == pytest.approx(math.pi / 2)
    assert F.yaw_enu_to_ned(math.pi / 2) == pytest.approx(0.0)  # nose north


def test_attitude_conversion_agrees_with_vector_conversions():
    """R_ned_frd · (FLU→FRD)(v) must equal (ENU→NED)(R_enu_flu · v) for every attitude."""
    for q in QUATS:
        q_ned = F.quat_enu_flu_to_ned_frd(q)
        assert np.linalg.norm(q_ned) == pytest.approx(1.0)
        for v in VECTORS[:5]:
            np.testing.assert_allclose(
                F.quat_rotate(q_ned, F.flu_to_frd(v)), F.enu_to_ned(F.quat_rotate(q, v)), atol=1e-12
            )


def test_euler_angles_describe_the_true_attitude():
    """The original code reported the inverse rotation (roll sign flipped)."""
    q = F.quat_from_axis_angle([1.0, 0.0, 0.0], 0.3)  # roll right-wing-down by 0.3 rad (FLU)
    np.testing.assert_allclose(F.euler_from_quat(q), [0.3, 0.0, 0.0], atol=1e-12)
    left_wing = F.quat_rotate(q, [0.0, 1.0, 0.0])
    assert left_wing[2] > 0  # positive roll about forward lifts the left side
    q = F.quat_from_axis_angle([0.0, 0.0, 1.0], 0.7)
    np.testing.assert_allclose(F.euler_from_quat(q), [0.0, 0.0, 0.7], atol=1e-12)


def test_euler_round_trip_and_composition_order():
    angles = np.column_stack(
        [rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)]
    )
    q = F.quat_from_euler(*angles.T)
    np.testing.assert_allclose(F.euler_from_quat(q), angles, atol=1e-9)
    # Z-Y-X intrinsic: q = q_yaw ⊗ q_pitch ⊗ q_roll.
    r, p, y = angles[0]
    composed = F.quat_multiply(
        F.quat_multiply(F.quat_from_axis_angle([0, 0, 1], y), F.quat_from_axis_angle([0, 1, 0], p)),
        F.quat_from_axis_angle([1, 0, 0], r),
    )
    np.testing.assert_allclose(composed, q[0], atol=1e-12)


def test_quaternion_helpers():
    q = QUATS[0]
    np.testing.assert_allclose(F.quat_multiply(q, F.quat_conjugate(q)), [1, 0, 0, 0], atol=1e-15)
    m = F.quat_to_matrix(q)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="non-zero"):
        F.quat_normalize([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="3 components"):
        F.enu_to_ned([1.0, 2.0])


def test_single_vector_rotation_equals_the_batched_one():
    rng = np.random.default_rng(5)
    q = F.quat_normalize(rng.normal(size=(50, 4)))
    v = rng.normal(size=(50, 3))
    batched = F.quat_rotate(q, v)
    single = np.array([F.quat_rotate(q[i], v[i]) for i in range(50)])
    np.testing.assert_allclose(single, batched, atol=1e-14)


def test_single_euler_angles_equal_the_batched_ones_also_at_the_poles():
    rng = np.random.default_rng(6)
    q = F.quat_normalize(rng.normal(size=(50, 4)))
    pole = F.quat_from_euler(0.3, math.pi / 2, -1.0)  # pitch ±90°: the clamp applies
    q = np.vstack([q, pole, -pole])
    batched = F.euler_from_quat(q)
    single = np.array([F.euler_from_quat(row) for row in q])
    np.testing.assert_allclose(single, batched, atol=1e-14)
    assert abs(batched[50, 1] - math.pi / 2) < 1e-6
