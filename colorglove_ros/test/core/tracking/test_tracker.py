"""Tests of core.tracking (kinematics, projection, solver, matching, tracker): Jacobian chain,
Gauss-Newton recovery, cameras, matching, tracker state."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hand_calibration_files import UNEVEN_FACTORS
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.mesh import build_hand_mesh
from colorglove_ros.core.hand.model import KEYPOINT_NAMES, HandModel
from colorglove_ros.core.lookup.types import ProjectionConstraints
from colorglove_ros.core.segmentation.blobs import extract_blobs
from colorglove_ros.core.segmentation.crop import CropTransform
from colorglove_ros.core.tracking.config import (
    IKConfig,
    IKConfigError,
    IKCovariances,
    default_covariances,
    load_covariances,
    load_ik_config,
    save_covariances,
)
from colorglove_ros.core.tracking.matching import match_by_color, match_extra_camera, match_primary
from colorglove_ros.core.tracking.projection import (
    estimate_translation,
    project_correspondences,
    reprojection_errors,
)
from colorglove_ros.core.tracking.solver import solve_ik
from colorglove_ros.core.tracking.tracker import HandTracker, away_from_border
from colorglove_ros.core.tracking.types import (
    Blobs,
    CameraObservation,
    Correspondences,
    IKError,
    PosePrior,
)

# the synthetic observations below put each blob at the projection of its constraint vertex,
# which is what the 'vertex' constraint model predicts (the 'patch' model is tested on renders)
VERTEX = IKConfig(constraint_model='vertex')
TIPS = [KEYPOINT_NAMES.index(f'{d}_tip') for d in ('thumb', 'index', 'middle', 'ring', 'little')]


@pytest.fixture(scope='module')
def rig(hand_kinematics):
    model, mesh, kin = hand_kinematics
    mono = load_calibration(CONFIG_DIR / 'calibration.yaml').cameras
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml').cameras
    # 20 constraint vertices spread over the hand (farthest-point sampling), one per patch
    P = mesh.skin(model, model.rest_pose())
    idx = [0]
    d = np.linalg.norm(P - P[0], axis=1)
    for _ in range(19):
        i = int(np.argmax(d))
        idx.append(i)
        d = np.minimum(d, np.linalg.norm(P - P[i], axis=1))
    return model, mesh, kin, mono, stereo, np.array(idx)


def true_pose(model: HandModel, rng: np.random.Generator) -> np.ndarray:
    q = model.rest_pose()
    q[2] = 0.55
    q[3:6] = rng.normal(0.0, 0.25, 3)
    q[6:] = 0.5 * rng.uniform(model.lower_limits[6:], model.upper_limits[6:])
    return model.clamp(q)


def synthetic_corr(rig, q, cams, rng, noise_px):
    model, mesh, kin, *_rest, verts = rig
    out = []
    for c, cam in enumerate(cams):
        pw, _ = kin.points(q, mesh.vertex_link[verts], mesh.local_vertices[verts])
        pix = cam.project(cam.world_to_camera(pw)) + rng.normal(0.0, noise_px, (len(verts), 2))
        out.append(Correspondences(np.full(len(verts), c), mesh.vertex_link[verts],
                                   mesh.local_vertices[verts], pix, np.arange(len(verts)), verts))
    return Correspondences.concat(out)


def pose_and_correspondences(rig, seed: int, cams, noise_px: float):
    """A seeded true pose and its synthetic correspondences in ``cams``, and the generator
    (for the test's further draws): (q, correspondences, rng)."""
    rng = np.random.default_rng(seed)
    q = true_pose(rig[0], rng)
    return q, synthetic_corr(rig, q, cams, rng, noise_px), rng


def tip_error(model, q, q_true):
    return float(np.linalg.norm(model.keypoints(q)[TIPS] - model.keypoints(q_true)[TIPS],
                                axis=1).mean())


def test_fast_kinematics_matches_model(rig):
    model, mesh, kin, *_ = rig
    rng = np.random.default_rng(3)
    q = model.clamp(model.rest_pose() + rng.normal(0.0, 0.6, 26))
    idx = rng.integers(0, mesh.num_vertices, 50)
    p, J = kin.points(q, mesh.vertex_link[idx], mesh.local_vertices[idx], jacobian=True)
    np.testing.assert_allclose(p, mesh.skin(model, q)[idx], atol=1e-12)
    np.testing.assert_allclose(J, mesh.vertex_jacobian(model, q, idx), atol=1e-12)


def test_jacobian_chain_matches_finite_differences(rig):
    model, mesh, kin, mono, stereo, verts = rig
    q, corr, _ = pose_and_correspondences(rig, 4, stereo, 0.0)
    _, J, _ = project_correspondences(kin, stereo, corr, q, jacobian=True)
    assert J.shape == (2 * len(corr), 26)
    h = 1e-6
    J_fd = np.empty_like(J)
    for i in range(26):
        dq = np.zeros(26)
        dq[i] = h
        plus, _, _ = project_correspondences(kin, stereo, corr, q + dq)
        minus, _, _ = project_correspondences(kin, stereo, corr, q - dq)
        J_fd[:, i] = (plus - minus).reshape(-1) / (2 * h)
    scale = np.abs(J_fd).max()
    assert np.abs(J - J_fd).max() < 1e-5 * scale
    # the second camera's rows really involve its rotation (differ from the primary's)
    assert np.abs(J[:2 * len(verts)] - J[2 * len(verts):]).max() > 0.1 * scale


def test_one_camera_recovers_perturbed_pose(rig):
    model, mesh, kin, mono, stereo, verts = rig
    errors, starts, reproj = [], [], []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        q_true = true_pose(model, rng)
        q0 = q_true.copy()
        q0[0:3] += rng.normal(0.0, [0.01, 0.01, 0.03])
        q0[3:6] += rng.normal(0.0, 0.1, 3)
        q0[6:] += rng.normal(0.0, 0.15, 20)
        q0 = model.clamp(q0)
        corr = synthetic_corr(rig, q_true, mono, rng, 0.0)
        wide = IKCovariances([1.0, 1.0], np.full(26, 1.0), np.full(26, 1.0))
        sol = solve_ik(kin, mono, corr, q0, q0, wide, max_iterations=15)
        assert sol.cost < sol.initial_cost
        errors.append(tip_error(model, sol.q, q_true))
        starts.append(tip_error(model, q0, q_true))
        pix, _, _ = project_correspondences(kin, mono, corr, sol.q)
        reproj.append(np.linalg.norm(pix - corr.target_px, axis=1).mean())
    assert np.mean(starts) > 0.02
    assert np.mean(errors) < 0.004       # mean fingertip error under 4 mm
    assert np.mean(reproj) < 0.5


def test_two_cameras_cut_depth_error(rig):
    model, mesh, kin, mono, stereo, verts = rig
    cov = default_covariances()
    depth_err = {1: [], 2: []}
    for seed in range(8):
        for ncam, cams in ((1, stereo[:1]), (2, stereo)):
            rng = np.random.default_rng(100 + seed)
            q_true = true_pose(model, rng)
            q_b = q_true.copy()
            q_b[2] += 0.06                      # blended pose 6 cm too far
            q_b[6:] += rng.normal(0.0, 0.2, 20)
            q_b = model.clamp(q_b)
            corr = synthetic_corr(rig, q_true, cams, rng, 2.0)
            sol = solve_ik(kin, cams, corr, q_b, q_b, cov, max_iterations=10)
            depth_err[ncam].append(abs(sol.q[2] - q_true[2]))
    mono_err, stereo_err = np.mean(depth_err[1]), np.mean(depth_err[2])
    assert stereo_err < 0.005
    assert stereo_err < 0.3 * mono_err


def test_joint_limits_respected(rig):
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(7)
    q_true = true_pose(model, rng)
    q_true[6:] = model.lower_limits[6:] - 0.3      # hyper-extended: outside the limits
    corr = synthetic_corr(rig, q_true, mono, rng, 0.0)
    q0 = model.clamp(q_true)
    wide = IKCovariances([1.0, 1.0], np.full(26, 10.0), np.full(26, 10.0))
    sol = solve_ik(kin, mono, corr, q0, q0, wide, max_iterations=10)
    assert model.within_limits(sol.q)
    assert np.all(sol.q[6:] >= model.lower_limits[6:])
    # fingers pinned at the lower bound (the nearest feasible flexion)
    flex = [i for i, n in enumerate(model.dof_names) if n.endswith('_flex') and 'thumb' not in n]
    assert np.sum(np.abs(sol.q[flex] - model.lower_limits[flex]) < 1e-6) >= 10
    assert np.all(sol.q[flex] - model.lower_limits[flex] < 0.2)


def test_translation_estimate_from_constraints(rig):
    model, mesh, kin, mono, stereo, verts = rig
    q_true, corr, _ = pose_and_correspondences(rig, 8, mono, 0.0)
    q_bad = q_true.copy()
    q_bad[0:3] = [0.05, -0.04, 0.35]
    q_fit = estimate_translation(kin, mono, corr, q_bad)
    np.testing.assert_allclose(q_fit[0:3], q_true[0:3], atol=1e-6)
    np.testing.assert_array_equal(q_fit[3:], q_bad[3:])
    # one wild target: the trimmed refit ignores it, the plain fit does not
    wild = Correspondences(corr.camera, corr.link, corr.local, corr.target_px.copy(),
                           corr.patch_id, corr.vertex)
    wild.target_px[0] += [80.0, 60.0]
    plain = estimate_translation(kin, mono, wild, q_bad)
    trimmed = estimate_translation(kin, mono, wild, q_bad, outlier_px=20.0)
    assert np.abs(plain[0:3] - q_true[0:3]).max() > 1e-3
    np.testing.assert_allclose(trimmed[0:3], q_true[0:3], atol=1e-6)


def test_translation_estimate_with_two_cameras_trims_per_camera_rows(rig):
    """The vectorised fit (rows of all cameras stacked per correspondence) recovers the
    translation from both cameras, and trims a wild target of the second camera only."""
    model, mesh, kin, mono, stereo, verts = rig
    q_true, corr, _ = pose_and_correspondences(rig, 9, stereo, 0.0)
    assert set(corr.camera.tolist()) == {0, 1}
    q_bad = q_true.copy()
    q_bad[0:3] += [0.03, -0.02, 0.06]
    np.testing.assert_allclose(estimate_translation(kin, stereo, corr, q_bad)[0:3],
                               q_true[0:3], atol=1e-6)
    target = corr.target_px.copy()
    target[np.flatnonzero(corr.camera == 1)[0]] += [70.0, -50.0]
    wild = replace(corr, target_px=target)
    assert np.abs(estimate_translation(kin, stereo, wild, q_bad)[0:3] - q_true[0:3]).max() > 1e-4
    np.testing.assert_allclose(
        estimate_translation(kin, stereo, wild, q_bad, outlier_px=20.0)[0:3], q_true[0:3],
        atol=1e-6)
    far_behind = q_true.copy()
    far_behind[2] = -1.0
    with pytest.raises(IKError, match='behind'):
        estimate_translation(kin, stereo, corr, far_behind, prior_var=np.full(3, 1e-12))


def test_match_by_color_picks_right_blob():
    pred = np.array([[10.0, 10.0], [100.0, 10.0], [50.0, 50.0]])
    pred_col = np.array([3, 3, 5])
    # two colour-3 blobs given in swapped order, a colour-5 blob near a colour-3 prediction,
    # a far colour-5 blob outside the gate
    blob = np.array([[102.0, 12.0], [12.0, 9.0], [11.0, 11.0], [400.0, 400.0]])
    blob_col = np.array([3, 3, 5, 5])
    k, m = match_by_color(pred, pred_col, blob, blob_col, gate_px=20.0)
    pairs = dict(zip(k.tolist(), m.tolist(), strict=True))
    assert pairs == {0: 1, 1: 0}


def test_projection_constraints_are_checked_and_converted():
    from colorglove_ros.core.validation import InvalidPriorError

    cons = ProjectionConstraints([4, 14], np.array([5, 5], np.uint8), [7, 9],
                                 [[5.0, 5.0], [30.0, 20.0]], [30, 40])
    assert len(cons) == 2 and cons.full_xy is None
    assert cons.colors.dtype == np.int64 and cons.pixel_counts.dtype == float
    empty = ProjectionConstraints([], [], [], [], [])
    assert len(empty) == 0 and empty.tiny_xy.shape == (0, 2)
    with pytest.raises(InvalidPriorError, match='same length'):
        ProjectionConstraints([4, 14], [5, 5], [7, 9], [[5.0, 5.0]], [30, 40])
    with pytest.raises(InvalidPriorError, match='same length'):
        ProjectionConstraints([4], [5], [7], [[5.0, 5.0]], [30], full_xy=[[1.0, 2.0], [3, 4]])
    with pytest.raises(InvalidPriorError, match='tiny_xy'):
        ProjectionConstraints([4], [5], [7], [[5.0, 5.0, 1.0]], [30])


def test_match_primary_uses_crop(rig):
    model, mesh, kin, mono, stereo, verts = rig
    crop = CropTransform(scale=4.0, offset_x=200.0, offset_y=100.0)
    cons = ProjectionConstraints([4, 14], [5, 5], verts[:2], [[5.0, 5.0], [30.0, 20.0]], [30, 40])
    # full-image positions 220,120 and 320,180; blobs listed the other way round plus noise
    blobs = Blobs([5, 5, 2], [[322.0, 181.0], [219.0, 118.0], [221.0, 120.0]], [100, 90, 80])
    corr = match_primary(cons, blobs, crop, mono[0], mesh)
    order = np.argsort(corr.patch_id)
    np.testing.assert_array_equal(corr.patch_id[order], [4, 14])
    np.testing.assert_allclose(corr.target_px[order], [[219.0, 118.0], [322.0, 181.0]])
    np.testing.assert_array_equal(corr.vertex[order], verts[:2])


def _one_blob_with_clutter(verts: np.ndarray
                           ) -> tuple[CropTransform, ProjectionConstraints, Blobs]:
    """A crop at scale 4, four constraints whose entry patches hold 10 tiny pixels (160 image
    pixels) each, and their blobs at 220,120 / 260,140 / 320,180 / 280,220, patch 9's holding
    2.5 times its pixels (clutter)."""
    crop = CropTransform(scale=4.0, offset_x=200.0, offset_y=100.0)
    cons = ProjectionConstraints([4, 9, 14, 19], [5, 3, 5, 7], verts[:4],
                                 [[5.0, 5.0], [15.0, 10.0], [30.0, 20.0], [20.0, 30.0]],
                                 [10, 10, 10, 10])
    blobs = Blobs([5, 3, 5, 7], [[221.0, 120.0], [262.0, 141.0], [320.0, 181.0],
                                 [279.0, 221.0]], [150, 400, 170, 140])
    return crop, cons, blobs


@pytest.mark.parametrize('ratio, kept', [(0.0, [4, 9, 14, 19]), (2.0, [4, 14, 19]),
                                          (1.2, [4, 9, 14, 19])])
def test_match_primary_drops_blobs_far_larger_than_their_patch(rig, ratio, kept):
    """A blob holding more than max_blob_ratio times its constraint's entry pixels (tiny
    pixels x crop scale^2) is not matched, unless fewer than min_kept pairs would remain."""
    model, mesh, kin, mono, stereo, verts = rig
    crop, cons, blobs = _one_blob_with_clutter(verts)
    min_kept = 4 if ratio == 1.2 else 3
    corr = match_primary(cons, blobs, crop, mono[0], mesh, max_blob_ratio=ratio,
                         min_kept=min_kept)
    np.testing.assert_array_equal(np.sort(corr.patch_id), kept)


def test_tracker_passes_max_blob_ratio_to_matching(rig):
    """IKConfig.max_blob_ratio (config/ik.yaml) reaches the primary camera's matching."""
    from colorglove_ros.core.tracking.types import CameraObservation, PosePrior

    model, mesh, kin, mono, stereo, verts = rig
    crop, cons, blobs = _one_blob_with_clutter(verts)
    prior = PosePrior(true_pose(model, np.random.default_rng(3)), cons)
    seen = [CameraObservation(True, blobs, crop)]
    for ratio, n in ((0.0, 4), (2.0, 3)):
        tracker = HandTracker(model, mesh, mono, IKConfig(max_blob_ratio=ratio))
        corr0, _ = tracker._match_start(prior, seen, tracker._blend_start(prior))
        assert len(corr0) == n
    with pytest.raises(IKConfigError):
        IKConfig(max_blob_ratio=-1.0)


def test_extra_camera_matching_survives_depth_error(rig):
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(9)
    q_true = true_pose(model, rng)
    colors = np.arange(20) % 10 + 1
    cons = ProjectionConstraints(np.arange(20), colors, verts, np.zeros((20, 2)), np.full(20, 30))
    cam = stereo[1]
    pw_true, _ = kin.points(q_true, mesh.vertex_link[verts], mesh.local_vertices[verts])
    blob_xy = cam.project(cam.world_to_camera(pw_true))
    blobs = Blobs(colors, blob_xy + rng.normal(0.0, 1.0, (20, 2)), np.full(20, 50))
    q_pred = q_true.copy()
    q_pred[2] += 0.07                          # depth off by 7 cm
    pw, _ = kin.points(q_pred, mesh.vertex_link[verts], mesh.local_vertices[verts])
    corr = match_extra_camera(1, cam, cons, pw, blobs, mesh)
    assert len(corr) >= 17
    assert np.all(corr.camera == 1)
    np.testing.assert_allclose(corr.target_px, blobs.centroid_px[corr.patch_id])


def test_extra_camera_skips_back_facing(rig):
    model, mesh, kin, mono, stereo, verts = rig
    q = true_pose(model, np.random.default_rng(10))
    cons = ProjectionConstraints(np.arange(20), COLORS, verts, np.zeros((20, 2)), np.full(20, 30))
    cam = stereo[1]
    pw, _ = kin.points(q, mesh.vertex_link[verts], mesh.local_vertices[verts])
    blobs = Blobs(COLORS, cam.project(cam.world_to_camera(pw)), np.full(20, 50))
    center = -cam.rotation.T @ cam.translation
    toward = (center - pw) / np.linalg.norm(center - pw, axis=1, keepdims=True)
    normals = np.where(np.arange(20)[:, None] < 8, -toward, toward)   # first 8 face away
    corr = match_extra_camera(1, cam, cons, pw, blobs, mesh, normals_world=normals)
    assert sorted(corr.patch_id.tolist()) == list(range(8, 20))


def test_extract_blobs():
    labels = np.zeros((40, 60), np.uint8)
    labels[5:10, 5:10] = 3
    labels[20:30, 40:50] = 3
    labels[30:32, 2:4] = 7
    labels[0, 59] = 2                          # single pixel: below min_pixels
    b = extract_blobs(labels, min_pixels=4)
    found = sorted(zip(b.color.tolist(), b.pixel_count.tolist(), strict=True))
    assert found == [(3, 25), (3, 100), (7, 4)]
    c = b.centroid_px[np.argmax(b.pixel_count)]
    np.testing.assert_allclose(c, [44.5, 24.5])


# ---------------------------------------------------------------------------- tracker
CROP = CropTransform(scale=6.0, offset_x=200.0, offset_y=120.0)
COLORS = np.arange(20) % 10 + 1


def observe(rig, q_true, q_blend, cams, rng, noise_px=1.0, tiny_noise=0.3):
    model, mesh, kin, *_rest, verts = rig
    pw, _ = kin.points(q_true, mesh.vertex_link[verts], mesh.local_vertices[verts])
    obs = []
    for cam in cams:
        pix = cam.project(cam.world_to_camera(pw))
        obs.append(CameraObservation(True, Blobs(COLORS, pix + rng.normal(0, noise_px, pix.shape),
                                                 np.full(20, 60)), CROP))
    pix0 = cams[0].project(pw)
    tiny = CROP.to_tiny(pix0) + rng.normal(0.0, tiny_noise, pix0.shape)
    prior = PosePrior(q_blend, ProjectionConstraints(np.arange(20), COLORS, verts, tiny,
                                                np.full(20, 30)))
    return prior, obs


def observe_with_finger_error(rig, seed: int, cams):
    """A true pose, a blend 0.1 rad off on every finger DOF (clamped), and what ``cams`` see of
    the true pose (0.5 px blob noise): (q, q_blend, prior, observations)."""
    model = rig[0]
    rng = np.random.default_rng(seed)
    q = true_pose(model, rng)
    q_b = q.copy()
    q_b[6:] += rng.normal(0.0, 0.1, 20)
    q_b = model.clamp(q_b)
    prior, obs = observe(rig, q, q_b, cams, rng, noise_px=0.5)
    return q, q_b, prior, obs


def run_sequence(rig, cams, mode, n=30, seed=0):
    model, mesh, kin, *_ = rig
    rng = np.random.default_rng(seed)
    tracker = HandTracker(model, mesh, cams, VERTEX.with_mode(mode))
    base = true_pose(model, np.random.default_rng(42))
    out, truth = [], []
    for i in range(n):
        q_true = base.copy()
        q_true[0] += 0.002 * i
        q_true[6:] = model.clamp(base + 0.1 * np.sin(0.1 * i))[6:]
        q_b = q_true.copy()
        q_b[0:3] += rng.normal(0.0, 0.01, 3)
        q_b[3:6] += rng.normal(0.0, 0.05, 3)
        q_b[6:] += rng.normal(0.0, 0.1, 20)
        prior, obs = observe(rig, q_true, model.clamp(q_b), cams, rng, noise_px=2.0)
        res = tracker.update(prior, obs, stamp=i / 30.0)
        assert res.found
        out.append(res)
        truth.append(q_true)
    return out, np.array(truth)


def jitter(Q: np.ndarray) -> float:
    avg = np.stack([Q[i - 2:i + 3].mean(axis=0) for i in range(2, len(Q) - 2)])
    return float(np.abs(Q[2:-2] - avg).mean())


def test_smoothing_lowers_jitter(rig):
    model, mesh, kin, mono, stereo, verts = rig
    res_ik, truth = run_sequence(rig, mono, 'ik')
    res_sm, _ = run_sequence(rig, mono, 'ik_smooth')
    q_ik = np.array([r.q for r in res_ik])
    q_sm = np.array([r.q for r in res_sm])
    assert not res_ik[5].smoothed and res_sm[5].smoothed
    j_ik, j_sm = jitter(q_ik[:, 6:]), jitter(q_sm[:, 6:])
    assert j_sm < 0.7 * j_ik
    # without losing accuracy: finger error against the truth no worse than 10 %
    e_ik = np.abs(q_ik[:, 6:] - truth[:, 6:]).mean()
    e_sm = np.abs(q_sm[:, 6:] - truth[:, 6:]).mean()
    assert e_sm < 1.1 * e_ik
    # IK beats the blended pose on reprojection error
    res_b, _ = run_sequence(rig, mono, 'blend')
    assert np.mean([r.reprojection_error_px for r in res_ik]) < \
        0.7 * np.mean([r.reprojection_error_px for r in res_b])


def test_tracker_two_cameras(rig):
    model, mesh, kin, mono, stereo, verts = rig
    res, truth = run_sequence(rig, stereo, 'ik_smooth', n=8)
    # vertices facing away from the second camera are not matched there
    assert all(6 <= r.constraints_per_camera[1] <= 16 for r in res)
    assert all(r.reprojection_error_per_camera[1] < 5.0 for r in res)
    depth = np.abs(np.array([r.q[2] for r in res]) - truth[:, 2])
    assert depth.mean() < 0.01


def test_patches_seen_by_second_camera_only_count(rig):
    model, mesh, kin, mono, stereo, verts = rig
    q, q_b, prior, obs = observe_with_finger_error(rig, 13, stereo)
    b0 = obs[0].blobs
    keep = np.array([0, 1])                     # the primary camera sees two patches only
    obs[0] = CameraObservation(True, Blobs(b0.color[keep], b0.centroid_px[keep],
                                           b0.pixel_count[keep]), CROP)
    res = HandTracker(model, mesh, stereo, VERTEX).update(prior, obs, 0.0)
    assert res.constraints_per_camera[0] == 2 and res.constraints_per_camera[1] >= 6
    assert res.iterations > 0
    assert res.reprojection_error_per_camera[1] < 3.0
    assert tip_error(model, res.q, q) < tip_error(model, q_b, q)


def test_tracker_resets_when_hand_lost(rig):
    model, mesh, kin, mono, stereo, verts = rig
    tracker = HandTracker(model, mesh, mono, VERTEX)
    rng = np.random.default_rng(5)
    q = true_pose(model, rng)
    prior, obs = observe(rig, q, q, mono, rng)
    r1 = tracker.update(prior, obs, 0.0)
    r2 = tracker.update(prior, obs, 1 / 30)
    assert r1.found and r2.found and r2.smoothed and not r1.smoothed
    lost = tracker.update(prior, [CameraObservation(False)], 2 / 30)
    assert not lost.found and lost.q is None and lost.reset
    assert tracker.previous_pose is None
    r3 = tracker.update(prior, obs, 3 / 30)
    assert r3.found and not r3.smoothed
    nothing = tracker.update(None, obs, 4 / 30)
    assert not nothing.found and tracker.previous_pose is None
    tracker.update(prior, obs, 5 / 30)
    late = tracker.update(prior, obs, 5 / 30 + 1.0)       # gap longer than max_gap_s
    assert late.found and late.reset and not late.smoothed
    assert late.num_constraints == 20 and late.iterations > 0


def test_tracker_from_calibration_uses_hand_length():
    cal = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml')
    tracker = HandTracker.from_calibration(cal, load_ik_config(CONFIG_DIR / 'ik.yaml'))
    assert tracker.model.hand_length_m == pytest.approx(cal.hand_length_m)
    assert len(tracker.cameras) == 2
    with pytest.raises(IKError, match='mesh'):
        HandTracker.from_calibration(cal, mesh=build_hand_mesh(HandModel(0.17)))


def test_tracker_from_calibration_uses_finger_proportions():
    """The calibration's finger length factors reach the tracker's model, mesh and (with
    constraint_model patch) the standard glove's patches on the stretched mesh."""
    cal = replace(load_calibration(CONFIG_DIR / 'calibration.yaml'),
                  finger_length_factors=UNEVEN_FACTORS)
    tracker = HandTracker.from_calibration(cal, load_ik_config(CONFIG_DIR / 'ik.yaml'))
    assert tracker.model.finger_length_factors == UNEVEN_FACTORS
    assert tracker.mesh.finger_length_factors == UNEVEN_FACTORS
    assert tracker.model.hand_length_m == pytest.approx(cal.hand_length_m)
    standard = HandModel(cal.hand_length_m)
    assert not np.allclose(tracker.model.digit_lengths_m, standard.digit_lengths_m)
    patched = HandTracker.from_calibration(cal, IKConfig(constraint_model='patch'))
    assert patched.mesh is tracker.mesh
    with pytest.raises(IKError, match='finger length factors'):
        HandTracker.from_calibration(cal, mesh=build_hand_mesh(standard))


def test_tracker_accepts_lookup_result(rig):
    from colorglove_ros.core.lookup.types import LookupResult
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(12)
    q = true_pose(model, rng)
    prior, obs = observe(rig, q, q, mono, rng)
    c = prior.constraints
    lookup = LookupResult(
        np.arange(3), np.zeros(3), np.full(3, 1 / 3), np.tile(q, (3, 1)), q,
        ProjectionConstraints(c.patch_ids, c.colors.astype(np.uint8), c.vertices, c.tiny_xy,
                              c.pixel_counts, full_xy=CROP.to_full(c.tiny_xy)), 3)
    res = HandTracker(model, mesh, mono, VERTEX).update(lookup, obs, 0.0)
    assert res.found and res.num_constraints == 20
    assert tip_error(model, res.q, q) < 0.005


def test_blend_mode_fits_translation_only(rig):
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(6)
    q = true_pose(model, rng)
    q_b = q.copy()
    q_b[0:3] += [0.03, -0.02, 0.1]
    prior, obs = observe(rig, q, q_b, mono, rng, noise_px=0.0, tiny_noise=0.0)
    res = HandTracker(model, mesh, mono, VERTEX.with_mode('blend')).update(prior, obs, 0.0)
    assert res.iterations == 0
    np.testing.assert_allclose(res.q[3:], q_b[3:], atol=1e-12)
    # the translation prior (Q) pulls a little toward the blend: under 1 mm here
    np.testing.assert_allclose(res.q[0:3], q[0:3], atol=1e-3)
    assert res.reprojection_error_px < 0.5


def test_wrong_match_is_rejected(rig):
    model, mesh, kin, mono, stereo, verts = rig
    q, _, prior, obs = observe_with_finger_error(rig, 11, mono)
    moved = obs[0].blobs.centroid_px.copy()
    moved[3] += [30.0, -25.0]                 # a spurious blob, still inside the match gate
    obs = [CameraObservation(True, Blobs(COLORS, moved, np.full(20, 60)), CROP)]
    errs = {}
    for outlier_px in (0.0, 20.0):
        cfg = replace(VERTEX, outlier_px=outlier_px, enable_smoothing=False)
        res = HandTracker(model, mesh, mono, cfg).update(prior, obs, 0.0)
        errs[outlier_px] = tip_error(model, res.q, q)
        if outlier_px:
            assert res.num_rejected == 1 and res.num_constraints == 19
            assert 3 not in res.correspondences.patch_id
    assert errs[20.0] < 0.8 * errs[0.0]


# ---------------------------------------------------------------------------- configuration
def test_config_file_loads():
    cfg = load_ik_config(CONFIG_DIR / 'ik.yaml')
    assert cfg.enable_ik and cfg.enable_smoothing
    np.testing.assert_allclose(cfg.covariances.r_var_px2, [9.0, 9.0])
    np.testing.assert_allclose(cfg.covariances.q_var[2], 0.08**2)
    np.testing.assert_allclose(cfg.covariances.p_var[6:], 0.12**2)
    assert cfg.with_mode('blend').enable_ik is False
    with pytest.raises(IKConfigError):
        cfg.with_mode('fancy')


def test_covariance_file_round_trip_and_errors(tmp_path):
    cov = IKCovariances([4.0, 5.0], np.arange(1, 27) * 1e-3, np.arange(1, 27) * 1e-4)
    path = save_covariances(tmp_path / 'cov.yaml', cov, frames=12)
    back = load_covariances(path)
    np.testing.assert_allclose(back.q_var, cov.q_var)
    np.testing.assert_allclose(back.r_var_px2, [4.0, 5.0])
    (tmp_path / 'ik.yaml').write_text('version: 1\ncovariance_file: cov.yaml\nmax_iterations: 4\n')
    cfg = load_ik_config(tmp_path / 'ik.yaml')
    assert cfg.max_iterations == 4
    np.testing.assert_allclose(cfg.covariances.p_var, cov.p_var)
    bad = {
        'missing.yaml': None,
        'v2.yaml': path.read_text().replace('version: 1', 'version: 2'),
        'neg.yaml': path.read_text().replace('- 4.0', '- -4.0'),
        'other.yaml': 'format: something\nversion: 1\n',
        'broken.yaml': 'format: [unclosed\n',
    }
    for name, text in bad.items():
        if text is not None:
            (tmp_path / name).write_text(text)
        with pytest.raises(IKConfigError):
            load_covariances(tmp_path / name)
    (tmp_path / 'ik_bad.yaml').write_text('version: 1\ncovariance_file: nowhere.yaml\n')
    with pytest.raises(IKConfigError, match='not found'):
        load_ik_config(tmp_path / 'ik_bad.yaml')
    (tmp_path / 'ik_typo.yaml').write_text('version: 1\nmax_iteration: 4\n')
    with pytest.raises(IKConfigError, match='unknown setting'):
        load_ik_config(tmp_path / 'ik_typo.yaml')


def _dense_shift_reference(pred, kcol, bxy, bcol, shift_max_px, inlier_px):
    """The common image shift of match_extra_camera, scored on the dense (hypothesis,
    constraint, blob) array (the formulation the pair-list version must reproduce)."""
    same = kcol[:, None] == bcol[None, :]
    diff = bxy[None, :, :] - pred[:, None, :]
    hyp = diff[same]
    hyp = hyp[np.linalg.norm(hyp, axis=1) <= shift_max_px]
    res = diff[None] - hyp[:, None, None, :]
    dist = np.where(same[None], np.linalg.norm(res, axis=3), np.inf).min(axis=2)
    inl = dist <= inlier_px
    score = inl.sum(axis=1) - 1e-3 * np.where(inl, dist, 0.0).sum(axis=1) / inlier_px
    best = int(np.argmax(score))
    r = res[best]
    nearest = np.argmin(np.where(same, np.linalg.norm(r, axis=2), np.inf), axis=1)
    rows = np.flatnonzero(inl[best])
    return hyp[best] + r[rows, nearest[rows]].mean(axis=0)


@pytest.mark.parametrize('seed', range(6))
def test_extra_camera_shift_matches_dense_reference(rig, seed):
    """Shifted, noisy blobs with same-colour decoys and missing ones: the matched targets are
    those of the dense-array shift (a 30 px gate keeps the decoys out only with that shift)."""
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(seed)
    cam = stereo[1]
    q = true_pose(model, rng)
    colors = rng.integers(1, 6, 20)                         # 5 colours: 4 patches each
    cons = ProjectionConstraints(np.arange(20), colors, verts, np.zeros((20, 2)), np.full(20, 30))
    pw, _ = kin.points(q, mesh.vertex_link[verts], mesh.local_vertices[verts])
    pred = cam.project(cam.world_to_camera(pw))
    shift_true = rng.uniform(-60.0, 60.0, 2)
    seen = np.flatnonzero(rng.random(20) < 0.8)
    decoys = rng.uniform([0, 0], [cam.width, cam.height], (6, 2))
    bxy = np.concatenate([pred[seen] + shift_true + rng.normal(0.0, 1.5, (len(seen), 2)),
                          decoys])
    bcol = np.concatenate([colors[seen], rng.integers(1, 6, 6)])
    blobs = Blobs(bcol, bxy, np.full(len(bcol), 50))
    corr = match_extra_camera(1, cam, cons, pw, blobs, mesh)
    inside = np.flatnonzero((pred[:, 0] > -30) & (pred[:, 0] < cam.width + 30)
                            & (pred[:, 1] > -30) & (pred[:, 1] < cam.height + 30))
    shift = _dense_shift_reference(pred[inside], colors[inside], bxy, bcol, 150.0, 15.0)
    k, m = match_by_color(pred[inside] + shift, colors[inside], bxy, bcol, 30.0)
    np.testing.assert_array_equal(corr.patch_id, inside[k])
    np.testing.assert_allclose(corr.target_px, bxy[m])
    assert np.linalg.norm(shift - shift_true) < 2.0


def test_solution_residual_is_the_reprojection_error(rig):
    model, mesh, kin, mono, stereo, verts = rig
    q, corr, rng = pose_and_correspondences(rig, 12, stereo, 2.0)
    q0 = q.copy()
    q0[6:] += rng.normal(0.0, 0.1, 20)
    for iterations in (0, 1, 3):
        sol = solve_ik(kin, stereo, corr, q0, q0, default_covariances(), q0, iterations)
        np.testing.assert_allclose(sol.errors_px, reprojection_errors(kin, stereo, corr, sol.q),
                                   atol=1e-9)


def test_frames_cached_by_rotation_and_fingers_follow_the_translation(rig):
    model, mesh, kin, *_ = rig
    rng = np.random.default_rng(13)
    q = model.clamp(model.rest_pose() + rng.normal(0.0, 0.5, 26))
    idx = rng.integers(0, mesh.num_vertices, 30)
    kin.points(q, mesh.vertex_link[idx], mesh.local_vertices[idx])
    moved = q.copy()
    moved[0:3] += [0.05, -0.02, 0.1]                 # same rotation and fingers: cached frames
    p, J = kin.points(moved, mesh.vertex_link[idx], mesh.local_vertices[idx], jacobian=True)
    np.testing.assert_allclose(p, mesh.skin(model, moved)[idx], atol=1e-12)
    np.testing.assert_allclose(J, mesh.vertex_jacobian(model, moved, idx), atol=1e-12)


def test_ik_file_refuses_the_node_switches(tmp_path) -> None:
    """enable_ik / enable_smoothing live in one place (ik_node's parameters, the tools'
    --modes): an IK file that sets them is refused instead of being silently overridden."""
    from colorglove_ros.core.tracking.config import IKConfigError, load_ik_config

    text = (CONFIG_DIR / 'ik.yaml').read_text()
    assert 'enable_ik:' not in text
    path = tmp_path / 'ik.yaml'
    path.write_text(text + '\nenable_ik: false\n')
    with pytest.raises(IKConfigError, match='enable_ik'):
        load_ik_config(path)


@pytest.mark.parametrize('seed', [21, 22, 23])
def test_translation_prior_holds_the_previous_shape_while_tracking(rig, seed):
    """A close match whose blend has the hand's shape wrong (every finger straighter): the
    translation refit at the blend's shape puts the hand at another depth; while tracking,
    the refit at the previous output's shape keeps the depth the blobs show. The prior's
    rotation and fingers stay the blend's either way."""
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(seed)
    q = true_pose(model, rng)
    q_b = q.copy()
    q_b[6:] -= 0.35                      # straighter fingers: a larger hand in the image
    q_b = model.clamp(q_b)
    errors = {}
    for on in (False, True):
        tracker = HandTracker(model, mesh, mono, replace(VERTEX, shape_at_previous_pose=on))
        prior, obs = observe(rig, q, q, mono, np.random.default_rng(seed), noise_px=0.3)
        assert tracker.update(prior, obs, 0.0).found          # tracking the true shape
        prior, obs = observe(rig, q, q_b, mono, np.random.default_rng(seed + 1), noise_px=0.3)
        res = tracker.update(prior, obs, 1.0 / 30.0)
        np.testing.assert_allclose(res.q_prior[3:], res.q_blend[3:], atol=1e-12)
        errors[on] = abs(res.q_prior[2] - q[2])
    assert errors[False] > 0.01
    assert errors[True] < 0.2 * errors[False]


def test_translation_prior_ignores_the_previous_shape_without_smoothing(rig):
    """Without smoothing (the 'ik' mode: each frame on its own) the refit holds the blend's
    shape, as on a first frame."""
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(24)
    q = true_pose(model, rng)
    q_b = model.clamp(q - np.r_[np.zeros(6), np.full(20, 0.35)])
    cfg = replace(VERTEX, shape_at_previous_pose=True).with_mode('ik')
    tracker = HandTracker(model, mesh, mono, cfg)
    prior, obs = observe(rig, q, q, mono, rng, noise_px=0.3)
    tracker.update(prior, obs, 0.0)
    prior, obs = observe(rig, q, q_b, mono, rng, noise_px=0.3)
    res = tracker.update(prior, obs, 1.0 / 30.0)
    fresh = HandTracker(model, mesh, mono, cfg).update(prior, obs, 1.0 / 30.0)
    np.testing.assert_allclose(res.q_prior, fresh.q_prior, atol=1e-12)


def test_patch_points_predicted_at_the_previous_pose_while_tracking(rig):
    """With the patch constraint model, while tracking, each constraint stands for the
    visible part of its patch as the previous output shows it, not as the blend does (a
    close match whose blend is turned 0.6 rad): the correspondences are those a blend at the
    previous pose gives; with the setting off they are the turned blend's."""
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(25)
    q = true_pose(model, rng)
    q_b = q.copy()
    q_b[3:6] += [0.0, 0.6, 0.0]
    points = {}
    for on in (False, True):
        cfg = replace(IKConfig(), shape_at_previous_pose=on)
        tracker = HandTracker(model, mesh, mono, cfg)
        prior, obs = observe(rig, q, q, mono, np.random.default_rng(1), noise_px=0.3)
        tracker.update(prior, obs, 0.0)
        q_prev = tracker.previous_pose
        prior, obs = observe(rig, q, q_b, mono, np.random.default_rng(2), noise_px=0.0)
        points[on] = tracker._match_start(prior, obs, q_b)[0]
        at = HandTracker(model, mesh, mono, cfg)._match_start(
            prior, obs, model.clamp(q_prev) if on else q_b)[0]
        np.testing.assert_allclose(points[on].local, at.local, atol=1e-12)
        np.testing.assert_allclose(points[on].weight, at.weight, atol=1e-12)
    assert np.abs(points[True].local - points[False].local).max() > 1e-3


def test_blobs_the_border_cuts_are_not_followed(rig):
    cam = rig[3][0]
    blobs = Blobs([1, 2, 3, 4], [[320.0, 240.0], [5.0, 200.0], [300.0, cam.height - 3.0],
                                 [cam.width - 6.0, 100.0]], [400, 100, 64, 16])
    kept = away_from_border(CameraObservation(True, blobs, CROP, True), cam)
    # the centre blob and the small one 6 px from the right border (side 4) stay; the two
    # whose centroid is nearer to the border than their side go
    assert kept.blobs.color.tolist() == [1, 4] and kept.cut_by_border and kept.crop is CROP
    assert away_from_border(None, cam) is None
    lost = CameraObservation(False)
    assert away_from_border(lost, cam) is lost


def test_follow_fits_every_cameras_blobs_from_the_last_pose(rig):
    model, mesh, kin, mono, stereo, verts = rig
    rng = np.random.default_rng(21)
    q0 = true_pose(model, rng)
    tracker = HandTracker(model, mesh, stereo, VERTEX)
    fresh = HandTracker(model, mesh, stereo, VERTEX)
    prior, obs = observe(rig, q0, q0, stereo, rng)
    assert not fresh.follow(obs, 0.0).found           # nothing to follow from
    assert tracker.update(prior, obs, 0.0).found
    q1 = q0.copy()
    q1[0] += 0.01                                      # 1 cm sideways, fingers curling
    q1[6:] = model.clamp(q1 + 0.05)[6:]
    _, moved = observe(rig, q1, q1, stereo, rng, noise_px=0.5)
    out = tracker.follow(moved, 1 / 30)
    assert out.found and out.followed and not out.reset
    assert all(n >= 10 for n in out.constraints_per_camera)
    assert tip_error(model, out.q, q1) < 0.3 * tip_error(model, q0, q1)
    assert not tracker.follow(moved, 1 / 30 + 5.0).found     # after a gap: no track
    assert tracker.previous_pose is None
