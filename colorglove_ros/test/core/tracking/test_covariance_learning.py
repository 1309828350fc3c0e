"""Tests of core.tracking.covariance_learning: learning R, Q, P, covariance files (the local
average it learns about: test/core/evaluation/test_metrics.py)."""
from __future__ import annotations

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.geometry import align_rotation_vector
from colorglove_ros.core.tracking.config import load_ik_config, save_covariances
from colorglove_ros.core.tracking.covariance_learning import (
    CovarianceFloors,
    IKTrainingError,
    TrainingFrame,
    estimate_r,
    learn_covariances,
)
from colorglove_ros.core.tracking.types import Correspondences


def test_r_estimate_matches_known_noise():
    rng = np.random.default_rng(0)
    n = 4000
    res = rng.normal(0.0, [2.0, 3.0], (n, 2))
    np.testing.assert_allclose(estimate_r(res), [4.0, 9.0], rtol=0.1)
    with pytest.raises(IKTrainingError):
        estimate_r(res[:, :1])


def test_rotation_vectors_aligned_across_pi():
    axis = np.array([0.0, 0.0, 1.0])
    a = axis * (np.pi - 0.05)
    b = -axis * (np.pi - 0.05)                  # same rotation family, 0.1 rad apart
    np.testing.assert_allclose(align_rotation_vector(b, a), axis * (np.pi + 0.05), atol=1e-12)


@pytest.fixture(scope='module')
def training_sequence(hand_kinematics):
    model, mesh, kin = hand_kinematics
    cams = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml').cameras
    rng = np.random.default_rng(1)
    verts = rng.choice(mesh.num_vertices, 20, replace=False)
    n = 60
    base = model.rest_pose()
    base[2] = 0.55
    base[6:] = 0.3 * model.upper_limits[6:]
    base = model.clamp(base)
    vel = np.zeros(26)
    vel[0] = 0.003                             # x moves 3 mm a frame, the rest stands still
    vel[7] = 0.01
    q_sigma = np.concatenate([[0.01, 0.01, 0.05], [0.05] * 3, [0.1] * 20])
    frames = []
    for i in range(n):
        q_true = base + i * vel
        pw, _ = kin.points(q_true, mesh.vertex_link[verts], mesh.local_vertices[verts])
        corrs = []
        for c, cam in enumerate(cams):
            pix = cam.project(cam.world_to_camera(pw)) + rng.normal(0.0, 2.0, (20, 2))
            corrs.append(Correspondences(np.full(20, c), mesh.vertex_link[verts],
                                         mesh.local_vertices[verts], pix, np.arange(20), verts))
        q_blend = q_true + rng.normal(0.0, q_sigma)
        q_est = q_true + rng.normal(0.0, 1e-4, 26)
        frames.append(TrainingFrame(q_blend, Correspondences.concat(corrs), q_true, q_est))
    return model, cams, frames, q_sigma, vel


def test_learn_with_ground_truth(training_sequence, tmp_path):
    model, cams, frames, q_sigma, vel = training_sequence
    floors = CovarianceFloors()
    cov, stats = learn_covariances([frames], model, cams, floors=floors)
    assert stats['with_ground_truth'] == 1 and stats['frames'] == 60
    assert stats['residuals'] == 60 * 40
    np.testing.assert_allclose(cov.r_var_px2, [4.0, 4.0], rtol=0.15)
    ratio = cov.q_var / q_sigma**2
    assert 0.6 < np.median(ratio) < 1.4
    np.testing.assert_allclose(cov.p_var[0], vel[0] ** 2, rtol=1e-6)
    np.testing.assert_allclose(cov.p_var[7], vel[7] ** 2, rtol=1e-6)
    # DOFs that never moved are floored, not zero
    np.testing.assert_allclose(cov.p_var[1:3], floors.translation_m**2)
    np.testing.assert_allclose(cov.p_var[8:], floors.fingers_rad**2)
    # the learned file drives the tracker configuration
    save_covariances(tmp_path / 'ik_cov.yaml', cov, **stats)
    (tmp_path / 'ik.yaml').write_text('version: 1\ncovariance_file: ik_cov.yaml\n')
    cfg = load_ik_config(tmp_path / 'ik.yaml')
    np.testing.assert_allclose(cfg.covariances.q_var, cov.q_var)


def test_learn_from_estimates_only(training_sequence):
    model, cams, frames, q_sigma, vel = training_sequence
    no_truth = [TrainingFrame(f.q_blend, f.correspondences, None, f.q_estimate) for f in frames]
    cov, stats = learn_covariances([no_truth], model, cams)
    assert stats['with_ground_truth'] == 0 and stats['frames'] == 56   # 2 frames lost each end
    np.testing.assert_allclose(cov.r_var_px2, [4.0, 4.0], rtol=0.2)
    assert 0.6 < np.median(cov.q_var / q_sigma**2) < 1.4
    np.testing.assert_allclose(cov.p_var[0], vel[0] ** 2, rtol=0.05)


def test_learn_rejects_bad_input(training_sequence):
    model, cams, frames, *_ = training_sequence
    with pytest.raises(IKTrainingError, match='needs >= 5'):
        learn_covariances([frames[:3]], model, cams)
    mixed = [TrainingFrame(f.q_blend, f.correspondences) for f in frames[:10]]
    with pytest.raises(IKTrainingError, match='q_true'):
        learn_covariances([mixed], model, cams)
    empty = [TrainingFrame(f.q_blend, Correspondences.empty(), f.q_true) for f in frames[:10]]
    with pytest.raises(IKTrainingError, match='no correspondences'):
        learn_covariances([empty], model, cams)


def test_learn_from_tracker_run(training_sequence, hand_kinematics):
    """End to end: run the tracker on a synthetic sequence and learn from its outputs."""
    from colorglove_ros.core.lookup.types import ProjectionConstraints
    from colorglove_ros.core.segmentation.crop import CropTransform
    from colorglove_ros.core.tracking.config import IKConfig
    from colorglove_ros.core.tracking.covariance_learning import training_frame
    from colorglove_ros.core.tracking.tracker import HandTracker
    from colorglove_ros.core.tracking.types import Blobs, CameraObservation, PosePrior
    model, cams, frames, q_sigma, vel = training_sequence
    _, mesh, kin = hand_kinematics
    cam = cams[0]
    crop = CropTransform(scale=6.0, offset_x=200.0, offset_y=120.0)
    colors = np.arange(20) % 10 + 1
    rng = np.random.default_rng(2)
    # blobs at the constraint vertices' projections: the 'vertex' constraint model
    tracker = HandTracker(model, mesh, [cam], IKConfig(constraint_model='vertex').with_mode('ik'))
    out = []
    for f in frames[:30]:
        verts = f.correspondences.vertex[:20]
        pw, _ = kin.points(f.q_true, mesh.vertex_link[verts], mesh.local_vertices[verts])
        pix = cam.project(pw)
        obs = [CameraObservation(True, Blobs(colors, pix + rng.normal(0, 2.0, pix.shape),
                                             np.full(20, 60)), crop)]
        cons = ProjectionConstraints(np.arange(20), colors, verts, crop.to_tiny(pix),
                                     np.full(20, 30))
        res = tracker.update(PosePrior(f.q_blend, cons), obs, len(out) / 30)
        out.append(training_frame(res, f.q_true))
    cov, stats = learn_covariances([out], model, [cam])
    assert stats['residuals'] == 30 * 20
    assert 2.0 < cov.r_var_px2.mean() < 8.0                  # 2 px blob noise -> ~4 px^2
    finger_ratio = np.median(cov.q_var[6:] / q_sigma[6:] ** 2)
    assert 0.5 < finger_ratio < 1.6                          # prior fingers = blend fingers
    # the refitted translation is a better prior than the blend's: smaller Q than its noise
    assert cov.q_var[2] < 0.5 * q_sigma[2] ** 2
