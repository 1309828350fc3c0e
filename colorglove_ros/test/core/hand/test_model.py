"""Tests for the kinematic hand model: names, limits, rest pose, FK and analytic Jacobians."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.geometry import matrix_to_rotvec, rotvec_to_matrix, so3_left_jacobian
from colorglove_ros.core.hand.model import (
    DOF_NAMES,
    FINGER_DOF_NAMES,
    KEYPOINT_NAMES,
    NUM_DOFS,
    HandModel,
    HandModelError,
)


@pytest.fixture(scope='module')
def model() -> HandModel:
    return HandModel()


def random_pose(model: HandModel, rng: np.random.Generator, rot_scale: float = 2.5) -> np.ndarray:
    lo = model.lower_limits.copy()
    hi = model.upper_limits.copy()
    q = rng.uniform(np.nan_to_num(lo, neginf=0.0), np.nan_to_num(hi, posinf=0.0))
    q[0:3] = rng.uniform([-0.2, -0.2, 0.3], [0.2, 0.2, 0.8])
    axis = rng.normal(size=3)
    q[3:6] = axis / np.linalg.norm(axis) * rng.uniform(0.0, rot_scale)
    return q


def test_names_and_sizes(model: HandModel) -> None:
    assert NUM_DOFS == 26 and len(DOF_NAMES) == 26 and len(FINGER_DOF_NAMES) == 20
    assert DOF_NAMES[:6] == ('wrist_tx', 'wrist_ty', 'wrist_tz', 'wrist_rx', 'wrist_ry', 'wrist_rz')
    assert DOF_NAMES[6:10] == ('thumb_cmc_abd', 'thumb_cmc_flex', 'thumb_mcp_flex', 'thumb_ip_flex')
    assert DOF_NAMES[10:14] == ('index_mcp_abd', 'index_mcp_flex', 'index_pip_flex',
                                'index_dip_flex')
    assert DOF_NAMES[-1] == 'little_dip_flex'
    assert len(KEYPOINT_NAMES) == 21 and KEYPOINT_NAMES[0] == 'wrist'
    assert len(model.link_names) == 16 and model.link_names[0] == 'palm'
    assert model.link_parent[0] == -1 and np.all(model.link_parent[1:] < np.arange(1, 16))


def test_limits_from_notes(model: HandModel) -> None:
    i = DOF_NAMES.index
    assert model.lower_limits[i('index_mcp_flex')] == 0.0
    assert np.isclose(model.upper_limits[i('index_mcp_flex')], np.pi / 2)
    assert np.isclose(model.upper_limits[i('ring_pip_flex')], np.deg2rad(110))
    assert np.isclose(model.upper_limits[i('little_dip_flex')], np.deg2rad(90))
    assert np.isclose(model.lower_limits[i('middle_mcp_abd')], np.deg2rad(-15))
    assert np.all(np.isinf(model.lower_limits[3:6])) and np.all(np.isinf(model.upper_limits[3:6]))
    assert np.all(model.lower_limits < model.upper_limits)
    q = np.full(26, 5.0)
    c = model.clamp(q)
    assert np.all(c <= model.upper_limits) and np.all(c[3:6] == 5.0)
    assert model.within_limits(c) and not model.within_limits(q)


@pytest.mark.parametrize('length', [0.15, 0.19, 0.23])
def test_hand_length_and_rest_pose(length: float) -> None:
    m = HandModel(length)
    q = m.rest_pose()
    kp = m.keypoints(q)
    wrist, mid = kp[0], kp[KEYPOINT_NAMES.index('middle_tip')]
    assert np.isclose(np.linalg.norm(mid - wrist), length, atol=1e-12)
    assert np.isclose(wrist[2], 0.5)
    # fingers point up in the image (-y), palm faces the camera (back of hand is +z)
    for d in ('index', 'middle', 'ring', 'little'):
        tip = kp[KEYPOINT_NAMES.index(f'{d}_tip')]
        assert tip[1] < wrist[1] - 0.6 * length
        assert np.isclose(tip[2], 0.5)
    # right hand seen palm-on: thumb on the image right, little finger on the left
    assert kp[KEYPOINT_NAMES.index('thumb_tip')][0] > kp[KEYPOINT_NAMES.index('index_tip')][0]
    assert kp[KEYPOINT_NAMES.index('little_tip')][0] < kp[KEYPOINT_NAMES.index('ring_tip')][0]


def test_flexion_curls_toward_palm(model: HandModel) -> None:
    q = model.rest_pose()
    q[DOF_NAMES.index('index_mcp_flex')] = np.pi / 2
    kp = model.keypoints(q)
    tip = kp[KEYPOINT_NAMES.index('index_tip')]
    mcp = kp[KEYPOINT_NAMES.index('index_mcp')]
    # palm faces the camera (-z), so a 90 deg MCP flexion points the finger at the camera
    assert np.isclose(mcp[2] - tip[2], sum(model.link_lengths[4:7]), atol=1e-9)


def test_rotvec_roundtrip() -> None:
    rng = np.random.default_rng(1)
    r = rng.normal(size=(50, 3))
    r *= (rng.uniform(0, 3.1, 50) / np.linalg.norm(r, axis=1))[:, None]
    R = rotvec_to_matrix(r)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(matrix_to_rotvec(R), r, atol=1e-9)


@pytest.mark.parametrize('theta', [0.0, 1e-7, 0.3, 2.0, 3.1])
def test_left_jacobian(theta: float) -> None:
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    r = axis * theta
    Jl = so3_left_jacobian(r)
    R0 = rotvec_to_matrix(r)
    eps = 1e-6
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        dR = (rotvec_to_matrix(r + d) - rotvec_to_matrix(r - d)) / (2 * eps) @ R0.T
        w = np.array([dR[2, 1], dR[0, 2], dR[1, 0]])
        assert np.allclose(w, Jl[:, k], atol=1e-8)


@pytest.mark.parametrize('seed', range(6))
def test_keypoint_jacobian_matches_finite_differences(model: HandModel, seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = random_pose(model, rng)
    J = model.keypoint_jacobian(q)
    eps = 1e-6
    Jn = np.zeros_like(J)
    for i in range(NUM_DOFS):
        d = np.zeros(NUM_DOFS)
        d[i] = eps
        Jn[:, :, i] = (model.keypoints(q + d) - model.keypoints(q - d)) / (2 * eps)
    assert np.abs(J - Jn).max() < 1e-8
    assert np.abs(J).max() > 0.05  # non-trivial


def test_point_jacobian_random_points(model: HandModel) -> None:
    rng = np.random.default_rng(7)
    q = random_pose(model, rng)
    links = rng.integers(0, 16, 40)
    pts = rng.normal(scale=0.02, size=(40, 3))
    J = model.point_jacobian(q, links, pts)
    eps = 1e-6
    for i in range(NUM_DOFS):
        d = np.zeros(NUM_DOFS)
        d[i] = eps
        num = (model.transform_points(q + d, links, pts)
               - model.transform_points(q - d, links, pts)) / (2 * eps)
        assert np.abs(J[:, :, i] - num).max() < 1e-8
    # palm points do not depend on finger DOFs
    assert np.all(J[links == 0][:, :, 6:] == 0.0)


def test_batch_matches_single(model: HandModel) -> None:
    rng = np.random.default_rng(3)
    Q = np.stack([random_pose(model, rng) for _ in range(5)])
    Tb = model.link_transforms_batch(Q)
    assert Tb.shape == (5, 16, 4, 4)
    for b in range(5):
        assert np.allclose(Tb[b], model.link_transforms(Q[b]), atol=1e-14)
    R = Tb[..., :3, :3]
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(model.keypoints_batch(Q)[2], model.keypoints(Q[2]))


def test_global_pose_is_rigid(model: HandModel) -> None:
    rng = np.random.default_rng(4)
    q = random_pose(model, rng)
    q2 = q.copy()
    q2[:6] = 0.0
    a = model.keypoints(q)
    b = model.keypoints(q2)
    R = rotvec_to_matrix(q[3:6])
    assert np.allclose(a, b @ R.T + q[:3], atol=1e-12)


def test_coupling_prior(model: HandModel) -> None:
    C = model.coupling_prior()
    assert C.shape == (4, 26)
    q = model.rest_pose()
    q[DOF_NAMES.index('ring_pip_flex')] = 1.2
    q[DOF_NAMES.index('ring_dip_flex')] = 0.8
    assert np.allclose(C @ q, 0.0)
    q[DOF_NAMES.index('ring_dip_flex')] = 0.0
    assert np.isclose((C @ q)[2], -0.8)


def test_bad_input(model: HandModel) -> None:
    with pytest.raises(HandModelError):
        model.keypoints(np.zeros(20))
    with pytest.raises(HandModelError):
        HandModel(2.0)
