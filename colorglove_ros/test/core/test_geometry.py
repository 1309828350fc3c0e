"""Tests of the rotation conversions (core/geometry.py) against scipy.spatial.transform."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from colorglove_ros.core.geometry import (
    GeometryError,
    align_rotation_vector,
    matrix_to_rotvec,
    quaternion_to_rotvec,
    rotvec_to_matrix,
    rotvec_to_quaternion,
    so3_left_jacobian,
    vector_to_skew,
)


def _rotvecs(seed: int = 0, n: int = 200) -> np.ndarray:
    """Random rotation vectors with angles in [0, pi), plus zero, tiny, small and pi - eps."""
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    rv = axes * rng.uniform(0.0, np.pi, (n, 1))
    rv[0] = 0.0
    rv[1] = [1e-10, -2e-10, 0.0]
    rv[2] = [3e-7, 0.0, -1e-7]
    rv[3] = [0.0, 2e-5, 1e-6]
    rv[4] = axes[4] * (np.pi - 1e-9)
    return rv


def test_skew_is_the_cross_product() -> None:
    rng = np.random.default_rng(1)
    v, u = rng.normal(size=(10, 3)), rng.normal(size=(10, 3))
    K = vector_to_skew(v)
    np.testing.assert_allclose((K @ u[:, :, None])[:, :, 0], np.cross(v, u), atol=1e-15)
    np.testing.assert_array_equal(K, -np.swapaxes(K, -1, -2))
    assert vector_to_skew(np.zeros((2, 4, 3))).shape == (2, 4, 3, 3)


def test_rotvec_to_matrix_matches_scipy_and_round_trips() -> None:
    rv = _rotvecs()
    R = rotvec_to_matrix(rv)
    np.testing.assert_allclose(R, Rotation.from_rotvec(rv).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-14)
    np.testing.assert_allclose(matrix_to_rotvec(R), rv, atol=1e-8)
    # batch shapes are kept
    assert rotvec_to_matrix(rv.reshape(4, 50, 3)).shape == (4, 50, 3, 3)
    assert matrix_to_rotvec(R.reshape(4, 50, 3, 3)).shape == (4, 50, 3)


def test_matrix_to_rotvec_at_pi_has_angle_pi() -> None:
    r = np.array([0.0, np.pi, 0.0])
    back = matrix_to_rotvec(rotvec_to_matrix(r))
    assert np.linalg.norm(back) == pytest.approx(np.pi, abs=1e-12)
    np.testing.assert_allclose(rotvec_to_matrix(back), rotvec_to_matrix(r), atol=1e-14)


def test_left_jacobian_is_the_derivative_of_exp() -> None:
    eps = 1e-6
    for r in _rotvecs(2, 12):
        Jl = so3_left_jacobian(r)
        R0 = rotvec_to_matrix(r)
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            dR = (rotvec_to_matrix(r + d) - rotvec_to_matrix(r - d)) / (2 * eps) @ R0.T
            omega = np.array([dR[2, 1], dR[0, 2], dR[1, 0]])
            np.testing.assert_allclose(omega, Jl[:, k], atol=1e-7)


def test_quaternions_match_scipy_and_round_trip() -> None:
    rv = _rotvecs(4)
    q = rotvec_to_quaternion(rv)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert np.all(q[:, 3] >= 0.0)
    np.testing.assert_allclose(q, Rotation.from_rotvec(rv).as_quat(), atol=1e-15)
    assert rotvec_to_quaternion(rv.reshape(2, 100, 3)).shape == (2, 100, 4)
    assert rotvec_to_quaternion(rv[7]).shape == (4,)
    for scale in (1.0, -3.0, 1e-3):                      # any sign and norm
        back = np.array([quaternion_to_rotvec(scale * row) for row in q])
        np.testing.assert_allclose(back, rv, atol=1e-12)
        np.testing.assert_allclose(back, Rotation.from_quat(scale * q).as_rotvec(), atol=1e-12)


def test_quaternion_to_rotvec_takes_the_short_way_and_refuses_zero() -> None:
    q = Rotation.from_rotvec([0.0, 0.0, 3.0]).as_quat()
    back = quaternion_to_rotvec(-q)                      # same rotation, other sign
    np.testing.assert_allclose(back, [0.0, 0.0, 3.0], atol=1e-14)
    near_pi = quaternion_to_rotvec(np.array([1.0, 0.0, 0.0, 1e-17]))
    assert np.linalg.norm(near_pi) == pytest.approx(np.pi)
    np.testing.assert_array_equal(quaternion_to_rotvec(np.array([0.0, 0.0, 0.0, 2.0])), 0.0)
    with pytest.raises(GeometryError):
        quaternion_to_rotvec(np.zeros(4))


def test_align_rotation_vector_crosses_the_pi_wrap() -> None:
    ref = np.array([0.0, 0.0, np.pi - 0.05])
    r = np.array([0.0, 0.0, -(np.pi - 0.05)])          # same axis line, angle wrapped
    out = align_rotation_vector(r, ref)
    np.testing.assert_allclose(rotvec_to_matrix(out), rotvec_to_matrix(r), atol=1e-12)
    assert np.linalg.norm(out - ref) < 0.2
    np.testing.assert_array_equal(align_rotation_vector(np.zeros(3), ref), np.zeros(3))
