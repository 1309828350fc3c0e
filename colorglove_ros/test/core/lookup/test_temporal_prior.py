"""Tests of the temporal reweighting of lookup neighbours (core/lookup/temporal_prior.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from colorglove_ros.core.lookup.blend import blend_poses
from colorglove_ros.core.lookup.temporal_prior import (
    TemporalPriorError,
    pose_distances_rad,
    reweight_by_previous,
)
from colorglove_ros.core.lookup.types import LookupResult, ProjectionConstraints


def _result(poses: np.ndarray, weights: np.ndarray) -> LookupResult:
    k = len(poses)
    empty = np.zeros(0)
    cons = ProjectionConstraints(empty.astype(int), empty.astype(np.uint8), empty.astype(int),
                                 np.zeros((0, 2)), empty, full_xy=np.zeros((0, 2)))
    return LookupResult(np.arange(k), np.linspace(1.0, 2.0, k), weights, poses,
                        blend_poses(poses, weights), cons, 300)


def _pose(fingers: float, rotvec=(0.0, 0.0, 0.5), wrist=(0.0, 0.0, 0.5)) -> np.ndarray:
    q = np.zeros(26)
    q[0:3] = wrist
    q[3:6] = rotvec
    q[6:] = fingers
    return q


def test_weights_favour_the_neighbour_near_the_previous_pose():
    poses = np.stack([_pose(0.0), _pose(0.6), _pose(0.3)])
    res = _result(poses, np.array([0.5, 0.3, 0.2]))
    out = reweight_by_previous(res, _pose(0.6), math.radians(20.0))
    assert out.weights.sum() == pytest.approx(1.0)
    assert int(np.argmax(out.weights)) == 1
    assert out.weights[1] > res.weights[1] and out.weights[0] < res.weights[0]
    # the blended fingers move from the image blend towards the previous pose
    assert abs(out.blended[6] - 0.6) < abs(res.blended[6] - 0.6)
    np.testing.assert_allclose(out.blended, blend_poses(poses, out.weights))
    # everything but the weights and the blend is the lookup's
    assert out.constraints is res.constraints
    np.testing.assert_array_equal(out.indices, res.indices)
    np.testing.assert_array_equal(out.distances, res.distances)
    np.testing.assert_array_equal(res.weights, [0.5, 0.3, 0.2])      # input left alone


def test_weights_are_image_weights_times_the_gaussian_of_pose_distance():
    poses = np.stack([_pose(0.0), _pose(0.1), _pose(0.2)])
    w_img = np.array([0.2, 0.5, 0.3])
    tau = 0.7
    q_prev = _pose(0.05, rotvec=(0.0, 0.2, 0.5))
    out = reweight_by_previous(_result(poses, w_img), q_prev, tau)
    d = pose_distances_rad(poses, q_prev)
    expect = w_img * np.exp(-(d / tau) ** 2)
    np.testing.assert_allclose(out.weights, expect / expect.sum())


def test_no_previous_pose_leaves_the_result_unchanged():
    res = _result(np.stack([_pose(0.0), _pose(0.5)]), np.array([0.7, 0.3]))
    assert reweight_by_previous(res, None, 0.3) is res


def test_far_previous_pose_does_not_underflow():
    poses = np.stack([_pose(0.0), _pose(0.1)])
    out = reweight_by_previous(_result(poses, np.array([0.5, 0.5])), _pose(3.0), 0.01)
    assert np.all(np.isfinite(out.weights)) and out.weights.sum() == pytest.approx(1.0)
    assert out.weights[1] == pytest.approx(1.0)       # the nearer one takes everything


def test_rotation_near_pi_is_measured_across_the_wrap():
    # pi - 0.05 about +z and pi - 0.05 about -z are 0.1 rad apart, not ~2 pi
    a = _pose(0.0, rotvec=(0.0, 0.0, math.pi - 0.05))
    b = _pose(0.0, rotvec=(0.0, 0.0, -(math.pi - 0.05)))
    c = _pose(0.0, rotvec=(0.0, 0.0, math.pi - 0.6))
    d = pose_distances_rad(np.stack([b, c]), a)
    np.testing.assert_allclose(d, [0.1, 0.55], atol=1e-9)
    # the neighbour across the wrap is the consistent one, and the blend stays near pi
    out = reweight_by_previous(_result(np.stack([c, b]), np.array([0.5, 0.5])), a, 0.2)
    assert out.weights[1] > 0.99
    assert np.linalg.norm(out.blended[3:6]) == pytest.approx(math.pi - 0.05, abs=0.01)


@pytest.mark.parametrize('weight, expected', [(0.0, 0.0), (1.0, 0.4), (4.0, 0.8)])
def test_rotation_weight_scales_the_rotation_term(weight, expected):
    poses = _pose(0.0, rotvec=(0.4, 0.0, 0.0))[None]
    d = pose_distances_rad(poses, _pose(0.0, rotvec=(0.0, 0.0, 0.0)), weight)
    assert d[0] == pytest.approx(expected)


def test_wrist_translation_is_ignored():
    d = pose_distances_rad(_pose(0.2, wrist=(0.1, 0.0, 0.8))[None], _pose(0.2))
    assert d[0] == pytest.approx(0.0, abs=1e-7)


@pytest.mark.parametrize('tau, weight', [(0.0, 1.0), (-1.0, 1.0), (math.nan, 1.0),
                                         (0.3, -1.0)])
def test_bad_settings_raise(tau, weight):
    res = _result(np.stack([_pose(0.0)]), np.array([1.0]))
    with pytest.raises(TemporalPriorError):
        reweight_by_previous(res, _pose(0.0), tau, weight)


def test_bad_pose_shape_raises():
    res = _result(np.stack([_pose(0.0)]), np.array([1.0]))
    with pytest.raises(TemporalPriorError):
        reweight_by_previous(res, np.zeros(20), 0.3)
