"""DigitEyes line features as extra IK constraints, on a rendered hand mask with ground truth."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.synthetic.bare_hand import BareHandSequence
from colorglove_ros.core.tracking.config import default_covariances
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.line_constraints import glove_edge_image, line_constraints
from colorglove_ros.core.tracking.solver import solve_ik
from colorglove_ros.core.tracking.types import Correspondences
from colorglove_ros.paths import resolve_path


@pytest.fixture(scope='module')
def scene():
    cameras = load_calibration(resolve_path('config/calibration_stereo.yaml')).cameras
    seq = BareHandSequence(cameras[0], seed=5, num_frames=40, hold_frames=10)
    frames = seq.render_views(25, cameras)
    # the hand mask (patch_ids: 1 on the hand, 0 elsewhere) stands in for glove labels
    masks = [glove_edge_image(f.patch_ids) for f in frames]
    yield cameras, FastKinematics(seq.synth.model), seq.poses[25], masks
    seq.close()


def test_edge_image_is_the_glove_mask() -> None:
    labels = np.array([[0, 3], [10, 0]], np.uint8)
    assert np.array_equal(glove_edge_image(labels), [[0, 255], [255, 0]])
    assert glove_edge_image(None) is None


def test_residuals_vanish_at_the_truth_and_their_jacobian_is_exact(scene) -> None:
    cameras, kin, truth, masks = scene
    start = truth.copy()
    start[[8, 12, 16]] += 0.08
    lines = line_constraints(kin, cameras, masks, start, std_px=2.0)
    assert lines is not None and len(lines) >= 40
    r_true, _ = lines.residuals(truth, False)
    r_start, J = lines.residuals(start, True)
    assert np.sqrt(np.mean(r_true**2)) < 1.0 < np.sqrt(np.mean(r_start**2))
    # J is the Jacobian of the prediction: residual = target - prediction
    dq = np.zeros(26)
    dq[12] = 1e-6
    r_step, _ = lines.residuals(start + dq, False)
    assert np.allclose(-(r_step - r_start) / 1e-6, J[:, 12], atol=1e-3)
    assert np.allclose(lines.weights, 0.25)


@pytest.mark.parametrize('num_cameras', [1, 2])
def test_solver_with_only_line_constraints_turns_the_fingers_back(scene,
                                                                           num_cameras) -> None:
    cameras, kin, truth, masks = scene
    start = truth.copy()
    start[[10, 14]] += 0.1                         # index and middle abduction
    lines = line_constraints(kin, cameras[:num_cameras], masks[:num_cameras], start, 2.0)
    cov = default_covariances()
    sol = solve_ik(kin, cameras[:num_cameras], Correspondences.empty(), start, start, cov,
                   max_iterations=6, extra=lines)
    assert sol.residual_px.shape == (0, 2)
    moved = [10, 14]
    assert np.abs(sol.q[moved] - truth[moved]).max() < 0.5 * 0.1
    without = solve_ik(kin, cameras[:num_cameras], Correspondences.empty(), start, start, cov,
                       max_iterations=6)
    assert np.allclose(without.q, start)
