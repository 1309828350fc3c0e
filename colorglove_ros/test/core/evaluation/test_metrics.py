"""Accuracy, jitter and latency figures."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pose_samples import MODEL, hand_pose

from colorglove_ros.core.evaluation.metrics import (
    FINGERTIP_INDICES,
    MetricsError,
    deviation_from_local_average,
    dof_jitter,
    fingertip_error_split_mm,
    fingertip_errors_mm,
    jitter_mm,
    joint_angle_error_deg,
    latency_summary_ms,
    local_average,
    pose_accuracy,
    translation_errors_mm,
)


def _poses(count: int) -> np.ndarray:
    """``count`` poses at the rest pose's wrist, every finger DOF 0.3 + 0.1 sin(frame index)
    (clipped to its limits)."""
    return np.stack([hand_pose(np.full(20, 0.3 + 0.1 * np.sin(k))) for k in range(count)])


def test_fingertips_are_the_last_keypoint_of_each_digit() -> None:
    from colorglove_ros.core.hand.model import DIGITS, KEYPOINT_NAMES

    last_of_digit = [max(i for i, name in enumerate(KEYPOINT_NAMES) if name.startswith(f'{d}_'))
                     for d in DIGITS]
    assert FINGERTIP_INDICES.tolist() == last_of_digit
    assert [KEYPOINT_NAMES[i] for i in FINGERTIP_INDICES] == [f'{d}_tip' for d in DIGITS]


def test_identical_sequences_have_zero_error() -> None:
    poses = _poses(8)
    figures = pose_accuracy(MODEL, poses, poses)
    for key in ('joint_mae_deg', 'fingertip_mm', 'wrist_plane_mm', 'wrist_depth_mm'):
        assert figures[key] == pytest.approx(0.0, abs=1e-9)
    assert figures['jitter_mm'] == pytest.approx(figures['jitter_truth_mm'])


def test_joint_error_in_degrees() -> None:
    truth = _poses(3)
    estimated = truth.copy()
    estimated[:, 6:] += np.radians(2.0)
    np.testing.assert_allclose(joint_angle_error_deg(estimated, truth), 2.0)


def test_translation_split_into_plane_and_depth() -> None:
    truth = _poses(1)
    truth[0, 0:3] = [0.0, 0.0, 0.5]
    estimated = truth.copy()
    estimated[0, 0:3] = [0.003, -0.004, 0.52]
    plane, depth = translation_errors_mm(estimated, truth)
    assert plane[0] == pytest.approx(5.0) and depth[0] == pytest.approx(20.0)
    # a pure wrist shift moves every fingertip by the same amount, and nothing relative to it
    assert fingertip_errors_mm(MODEL, estimated, truth)[0] == pytest.approx(np.hypot(5, 20))
    assert fingertip_errors_mm(MODEL, estimated, truth, relative_to_wrist=True)[0] == \
        pytest.approx(0.0, abs=1e-9)


def test_wrist_rotation_error_counts_relative_to_wrist_but_not_in_the_hand_frame() -> None:
    truth = _poses(2)
    truth[:, 0:3] = [0.0, 0.0, 0.5]
    estimated = truth.copy()
    estimated[:, 3] += 0.1                     # 0.1 rad wrist rotation error only
    rel = fingertip_errors_mm(MODEL, estimated, truth, relative_to_wrist=True)
    split = fingertip_error_split_mm(MODEL, estimated, truth)
    assert np.all(rel > 5.0)                   # fingertips ~0.1-0.2 m from the wrist
    np.testing.assert_allclose(split['hand_frame'], 0.0, atol=1e-9)
    np.testing.assert_allclose(split['rotation_only'], rel)


def test_finger_error_shows_in_the_hand_frame_and_not_in_rotation_only() -> None:
    truth = _poses(2)
    estimated = truth.copy()
    estimated[:, 3:6] = [0.3, -0.2, 0.1]       # same rotation error in both poses ...
    truth[:, 3:6] = estimated[:, 3:6]
    estimated[:, 6:] += np.radians(5.0)        # ... and only the fingers differ
    split = fingertip_error_split_mm(MODEL, estimated, truth)
    np.testing.assert_allclose(split['rotation_only'], 0.0, atol=1e-9)
    np.testing.assert_allclose(split['hand_frame'],
                               fingertip_errors_mm(MODEL, estimated, truth), rtol=1e-9)
    assert np.all(split['hand_frame'] > 1.0)
    figures = pose_accuracy(MODEL, estimated, truth)
    assert figures['fingertip_hand_frame_mm'] == pytest.approx(split['hand_frame'].mean())


def test_local_average_and_dof_jitter() -> None:
    t = np.arange(10.0)[:, None]
    lin = np.hstack([2.0 * t, -t + 3.0])
    avg = local_average(lin)
    assert np.isnan(avg[:2]).all() and np.isnan(avg[-2:]).all()
    np.testing.assert_allclose(avg[2:-2], lin[2:-2])          # a line is its own average
    np.testing.assert_allclose(deviation_from_local_average(lin)[2:-2], 0.0, atol=1e-12)
    # any trailing shape: (N, 5, 3) fingertips average like (N, 15) columns
    cube = np.random.default_rng(0).normal(size=(9, 5, 3))
    np.testing.assert_array_equal(local_average(cube).reshape(9, 15),
                                  local_average(cube.reshape(9, 15)))
    alt = np.array([[1.0], [-1.0]] * 5)                        # +-1 alternating
    # mean of 5 alternating values = +-1/5, deviation = 1 - 1/5 = 0.8
    np.testing.assert_allclose(dof_jitter(alt), [0.8])
    with pytest.raises(MetricsError, match='at least 5 frames'):
        dof_jitter(alt[:4])
    with pytest.raises(MetricsError, match='window must be odd'):
        local_average(lin, window=4)


def test_local_average_sums_each_window_once() -> None:
    """Far from the origin and over many frames the average keeps full precision: each row
    is its own window's sum (a running sum would lose digits as it grows)."""
    x = 0.5 + 1e-3 * np.sin(np.arange(3000.0))[:, None]
    exact = np.array([math.fsum(x[i - 2:i + 3, 0]) / 5 for i in range(2, 2998)])
    np.testing.assert_allclose(local_average(x)[2:-2, 0], exact, rtol=0, atol=3e-16)


def test_jitter_sees_alternating_noise_not_smooth_motion() -> None:
    smooth = np.tile(MODEL.rest_pose(), (20, 1))
    smooth[:, 0] = np.linspace(0.0, 0.1, 20)    # constant velocity: the local average follows it
    assert jitter_mm(MODEL, smooth) < 1e-6
    noisy = smooth.copy()
    noisy[::2, 0] += 0.004
    assert jitter_mm(MODEL, noisy) > jitter_mm(MODEL, smooth) + 1.0
    assert np.isnan(jitter_mm(MODEL, smooth[:3]))


def test_latency_summary() -> None:
    summary = latency_summary_ms([0.010] * 95 + [0.100] * 5)
    assert summary['p50'] == pytest.approx(10.0)
    assert summary['max'] == pytest.approx(100.0)
    assert np.isnan(latency_summary_ms([])['p95'])
