"""The DigitEyes edge tracker on rendered bare-hand frames with ground truth."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.model import KEYPOINT_NAMES, HandModel
from colorglove_ros.core.synthetic.bare_hand import BareHandSequence
from colorglove_ros.core.tracking.edge_features import to_grey
from colorglove_ros.core.tracking.edge_fit import (
    PALM_ANGLES,
    EdgeFit,
    EdgeTrackerConfig,
    EdgeTrackerError,
    _robust,
    feature_points,
    line_rows,
    link_axis_residuals,
    measure_features,
    palm_rows,
    predict_features,
    stack_residuals,
    tip_residuals,
)
from colorglove_ros.core.tracking.edge_tracker import EdgeTracker, initialisation_pose
from colorglove_ros.paths import resolve_path

TIPS = [KEYPOINT_NAMES.index(f'{d}_tip') for d in ('thumb', 'index', 'middle', 'ring', 'little')]


@pytest.fixture(scope='module')
def rig():
    cameras = load_calibration(resolve_path('config/calibration_stereo.yaml')).cameras
    seq = BareHandSequence(cameras[0], seed=5, num_frames=40, hold_frames=10)
    frames = {i: [f.image_rgb for f in seq.render_views(i, cameras)] for i in (0, 20, 21, 22)}
    frames['empty'] = seq.render_empty_views(cameras)
    yield cameras, seq, frames
    seq.close()


def _tip_error_rel_wrist_mm(model: HandModel, q: np.ndarray, truth: np.ndarray) -> float:
    a, b = model.keypoints(q), model.keypoints(truth)
    return float(1e3 * np.linalg.norm((a[TIPS] - a[0]) - (b[TIPS] - b[0]), axis=1).mean())


def test_residuals_are_signed_distances_and_differences() -> None:
    normal = np.array([[0.0, 1.0]])
    r, J = link_axis_residuals(normal, np.array([2.0]), np.array([[5.0, 3.0]]),
                               np.array([[9.0, 0.5]]), np.ones((1, 2, 4)), 2 * np.ones((1, 2, 4)))
    assert np.allclose(r, [1.0, -1.5]) and np.allclose(J, [[1, 1, 1, 1], [2, 2, 2, 2]])
    r, J = tip_residuals(np.array([[3.0, 4.0]]), np.array([[1.0, 1.0]]), np.ones((1, 2, 3)))
    assert np.allclose(r, [2.0, 3.0]) and J.shape == (2, 3)


# one camera sees abduction (in the image plane) well but flexion toward it poorly; two
# cameras see flexion too (an abduction error must stay below half the finger spacing, or a
# finger locks onto its neighbour)
@pytest.mark.parametrize('num_cameras, dofs, delta', [(1, [10], 0.1),
                                                      (2, [8, 11, 15, 19], 0.15)])
def test_fit_pulls_a_perturbed_pose_back_to_the_truth(rig, num_cameras: int, dofs: list[int],
                                                      delta: float) -> None:
    cameras, seq, frames = rig
    tracker = EdgeTracker(seq.synth.model, cameras[:num_cameras])
    truth = seq.poses[20]
    start = truth.copy()
    start[dofs] += delta
    start[0:3] += [0.006, -0.004, 0.0]
    before = _tip_error_rel_wrist_mm(seq.synth.model, start, truth)
    fit = tracker.fit(frames[20][:num_cameras], start, rounds=3)
    after = _tip_error_rel_wrist_mm(seq.synth.model, fit.q, truth)
    assert abs(fit.q[0] - truth[0]) < 0.004
    assert fit.rms_px < tracker.config.max_rms_px
    if num_cameras == 1:
        assert np.abs(fit.q[dofs] - truth[dofs]).mean() < 0.5 * delta
    else:
        assert before > 5.0 and after < 0.5 * before


def test_tracker_initialises_on_the_held_pose_then_tracks(rig) -> None:
    cameras, seq, frames = rig
    tracker = EdgeTracker(seq.synth.model, cameras, EdgeTrackerConfig(init_hold_frames=3))
    assert np.allclose(seq.poses[0], tracker.init_pose)
    results = [tracker.update(frames[0]) for _ in range(3)]
    assert [r.q is None for r in results] == [True, True, False]
    assert results[-1].initialised and tracker.state == 'tracking'
    tracker.initialize(seq.poses[20])
    for i in (21, 22):
        out = tracker.update(frames[i])
        assert out.q is not None, out.reason
        assert _tip_error_rel_wrist_mm(seq.synth.model, out.q, seq.poses[i]) < 10.0


def test_tracker_reports_loss_instead_of_a_pose(rig) -> None:
    cameras, seq, frames = rig
    tracker = EdgeTracker(seq.synth.model, cameras[:1], EdgeTrackerConfig(loss_patience=2))
    tracker.initialize(seq.poses[20])
    blank = np.full_like(frames[20][0], 90)
    first, second = tracker.update([blank]), tracker.update([blank])
    assert first.q is None and not first.lost and 'poor fit' in first.reason
    assert second.q is None and second.lost and tracker.state == 'waiting'
    waiting = tracker.update([blank])
    assert waiting.q is None and 'waiting for the initialisation pose' in waiting.reason


def test_bad_inputs_are_refused(rig) -> None:
    cameras, seq, frames = rig
    tracker = EdgeTracker(seq.synth.model, cameras[:1])
    with pytest.raises(EdgeTrackerError):
        tracker.update(frames[0])                 # two images, one camera
    with pytest.raises(EdgeTrackerError):
        tracker.update([np.zeros((10, 10), np.uint8)])
    with pytest.raises(EdgeTrackerError):
        EdgeTracker(seq.synth.model, cameras[1:])  # primary must be the identity
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(tracked_links=('palm',))
    q = initialisation_pose(seq.synth.model, (0.0, 0.1, 0.5))
    assert q[2] == 0.5 and q[seq.synth.model.dof_names.index('index_mcp_abd')] > 0


def test_palm_outline_is_measured_where_the_true_pose_puts_it(rig) -> None:
    # the ulnar palm side's silhouette generator (chosen per camera from its view of the
    # palm: face-on and at 45 degrees) projects onto the measured outline at the true pose
    cameras, seq, frames = rig
    tracker = EdgeTracker(seq.synth.model, cameras)
    truth = seq.poses[20]
    for cam, image in zip(cameras, frames[20], strict=True):
        pred = predict_features(tracker.kin, tracker.points, cam, truth, tracker.config)
        meas = measure_features(to_grey(image), pred, tracker.config, tracker.points.tip_row)
        assert meas.palm_found.all()
        n, rho = meas.palm.normal[0], meas.palm.offset[0]
        assert abs(n @ pred.palm_base_px[0] - rho) < 2.0
        assert abs(n @ pred.palm_end_px[0] - rho) < 2.0
        # the palm rows come after the links and tips and move the wrist
        world = tracker.kin.points(truth, tracker.points.point_link, tracker.points.point_local,
                                   True)
        r, J, _ = stack_residuals(tracker.points, [cam], [meas], world, tracker.config)
        assert np.abs(J[-2:, 0:3]).sum() > 0


@pytest.mark.parametrize('found', [(True, False), (False, True), (True, True)])
def test_each_found_palm_side_gets_its_own_generator_rows(rig, found: tuple[bool, bool]) -> None:
    # with both palm sides, a camera that finds only one of them gives that side's line
    # the rows of that side's generator (not the first side's, nor one row per side)
    cameras, seq, frames = rig
    config = EdgeTrackerConfig(palm_sides=('ulnar', 'radial'))
    tracker = EdgeTracker(seq.synth.model, cameras, config)
    truth = seq.poses[20]
    pred = predict_features(tracker.kin, tracker.points, cameras[0], truth, config)
    meas = measure_features(to_grey(frames[20][0]), pred, config, tracker.points.tip_row)
    mask = np.array(found)
    meas = replace(meas, palm_found=mask)
    lines = line_rows(tracker.points, meas)
    n_link = lines.num_links
    A = len(PALM_ANGLES)
    stride = 2 * A + 1
    sides = np.flatnonzero(mask)
    k = pred.palm_generator[sides, 0].astype(np.int64)
    expected = tracker.points.palm_start + sides * stride + 2 * k
    assert np.array_equal(lines.base[n_link:], expected)
    assert np.array_equal(lines.end[n_link:], expected + 1)
    assert np.array_equal(lines.alpha[n_link:], pred.palm_generator[sides, 1])
    assert np.array_equal(lines.normal[n_link:], meas.palm.normal[sides])
    world = tracker.kin.points(truth, tracker.points.point_link, tracker.points.point_local,
                               True)
    r, J, w = stack_residuals(tracker.points, [cameras[0]], [meas], world, config)
    assert len(r) == len(J) == len(w)
    with pytest.raises(EdgeTrackerError):
        palm_rows(tracker.points, pred.palm_generator[sides], np.arange(len(sides) + 1))


def test_palm_sides_hold_the_wrist_tilt(rig) -> None:
    # without the palm, tilting the hand about its width while flexing the fingers at their
    # bases the other way changes few edges; with it, the fit comes back toward the truth
    cameras, seq, frames = rig
    truth = seq.poses[20]
    start = truth.copy()
    start[3] += 0.04
    for digit in ('index', 'middle', 'ring', 'little'):
        start[seq.synth.model.dof_names.index(f'{digit}_mcp_flex')] += 0.04
    errors = {}
    for sides in ((), ('ulnar',)):
        tracker = EdgeTracker(seq.synth.model, cameras,
                              EdgeTrackerConfig(palm_sides=sides, camera_weights=()))
        fit = tracker.fit(frames[20], start, rounds=3)
        errors[sides] = abs(fit.q[3] - truth[3])
    assert errors[('ulnar',)] < 0.005 < 0.5 * errors[()]


def test_cauchy_weights_all_but_ignore_a_far_measurement() -> None:
    r = np.array([0.5, 3.0, 12.0])
    huber = _robust(r, 3.0, 'huber')
    cauchy = _robust(r, 3.0, 'cauchy')
    assert np.allclose(huber, [1.0, 1.0, 0.25])
    assert np.allclose(cauchy, [1 / 1.0277777, 0.5, 1 / 17.0], atol=1e-6)
    assert cauchy[2] * r[2] < 0.5 * huber[2] * r[2]     # its pull on the pose is much smaller
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(robust_loss='tukey')


def test_found_fractions_per_camera_and_over_all_cameras(rig) -> None:
    cameras, seq, _ = rig
    q = seq.poses[20]
    fit = EdgeFit(q, 1.0, (14, 2), (14, 7), (5, 1), 3)       # 16 of 21 found, 2 of 7 in one
    strict = EdgeTracker(seq.synth.model, cameras,
                         EdgeTrackerConfig(min_camera_found_fraction=0.6))
    assert 'links found in camera2' in strict._fit_problem(fit)
    lenient = strict.with_config(min_camera_found_fraction=0.25)
    assert lenient._fit_problem(fit) == ''
    assert '(need 80%)' in lenient.with_config(min_found_fraction=0.8)._fit_problem(fit)


def test_fit_faults_are_told_apart_coverage_from_drift(rig) -> None:
    cameras, seq, _ = rig
    tracker = EdgeTracker(seq.synth.model, cameras,
                          EdgeTrackerConfig(min_camera_found_fraction=0.6))
    q = seq.poses[20]
    assert tracker._check_fit(EdgeFit(q, 1.0, (14, 2), (14, 7), (5, 1), 3))[0] == 'coverage'
    assert tracker._check_fit(EdgeFit(q, 5.0, (14, 7), (14, 7), (5, 1), 3))[0] == 'drift'
    assert tracker._check_fit(EdgeFit(q, np.nan, (0, 0), (14, 7), (0, 0), 0))[0] == 'drift'
    assert tracker._check_fit(EdgeFit(q, 1.0, (14, 7), (14, 7), (5, 1), 3)) == ('', '')


def test_tracker_coasts_through_frames_with_too_few_features(rig) -> None:
    cameras, seq, frames = rig
    config = EdgeTrackerConfig(loss_patience=1, coast_patience=2, resume_frames=1)
    tracker = EdgeTracker(seq.synth.model, cameras, config)
    tracker.initialize(seq.poses[20])
    # the second camera sees nothing: its links are missing, the first camera's agree
    half_blind = [frames[20][0], np.full_like(frames[20][1], 90)]
    coasted = [tracker.update(half_blind) for _ in range(2)]
    assert all(r.q is None and not r.lost and r.reason.startswith('coasting') for r in coasted)
    assert tracker.state == 'tracking'
    resumed = tracker.update(frames[21])
    assert resumed.q is None and 'resuming' in resumed.reason   # one good frame first
    out = tracker.update(frames[22])
    assert out.q is not None, out.reason
    assert _tip_error_rel_wrist_mm(seq.synth.model, out.q, seq.poses[22]) < 10.0
    # past coast_patience frames in a row the fault counts toward the loss
    for _ in range(2):
        tracker.update(half_blind)
    assert tracker.update(half_blind).lost and tracker.state == 'waiting'
    # without coasting the first such frame already counts toward the loss (patience 1)
    strict = tracker.with_config(coast_patience=0)
    strict.initialize(seq.poses[20])
    assert strict.update(half_blind).lost


def test_camera_weights_scale_each_cameras_residuals(rig) -> None:
    cameras, seq, frames = rig
    tracker = EdgeTracker(seq.synth.model, cameras, EdgeTrackerConfig(camera_weights=()))
    q = seq.poses[20]
    greys = [to_grey(img) for img in frames[20]]
    world = tracker.kin.points(q, tracker.points.point_link, tracker.points.point_local, True)
    measured = [measure_features(g, predict_features(tracker.kin, tracker.points, cam, q,
                                                     tracker.config, world),
                                 tracker.config, tracker.points.tip_row)
                for cam, g in zip(cameras, greys, strict=True)]
    _, _, w = stack_residuals(tracker.points, cameras, measured, world, tracker.config)
    weighted = EdgeTrackerConfig(camera_weights=(1.0, 0.25))
    assert EdgeTrackerConfig().camera_weights == (1.0, 0.25)
    _, _, w2 = stack_residuals(tracker.points, cameras, measured, world, weighted)
    first = len(stack_residuals(tracker.points, cameras[:1], measured[:1], world,
                                tracker.config)[0])
    assert np.allclose(w2[:first], w[:first]) and np.allclose(w2[first:], 0.25 * w[first:])
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(camera_weights=(1.0, -1.0))
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(coast_patience=-1)


def test_fingers_curled_behind_the_back_of_the_hand_are_not_searched() -> None:
    from colorglove_ros.core.hand.model import LINK_NAMES
    from colorglove_ros.core.tracking.mouse import MouseConfig
    from colorglove_ros.tools.eval_mouse import scripted_sequence

    calibration = load_calibration(resolve_path('config/calibration.yaml'))
    camera = calibration.cameras[0]
    model = HandModel(calibration.hand_length_m)
    # the mouse's relaxed hand on the table seen from behind at 45 degrees: the curled
    # fingers' middle and distal phalanges lie behind the knuckles
    q = scripted_sequence(model, MouseConfig(), seed=0, seconds=2.0, clicks=1)[0][0]
    seen = EdgeTracker(model, [camera])
    blind = seen.with_config(palm_occlusion_px=0.0)
    on = predict_features(seen.kin, seen.points, camera, q, seen.config)
    off = predict_features(blind.kin, blind.points, camera, q, blind.config)
    names = [LINK_NAMES[i] for i in seen.points.links]
    hidden = {n for n, a, b in zip(names, on.link_usable, off.link_usable, strict=True)
              if b and not a}
    assert {'index_middle', 'middle_middle'} <= hidden
    assert on.link_usable[names.index('thumb_distal')]          # the thumb stays in view
    assert on.link_usable.sum() < off.link_usable.sum()


def test_fingertip_disagreement_ignores_the_wrist_translation(rig) -> None:
    from colorglove_ros.core.tracking.edge_fit import fingertip_disagreement

    _, seq, _ = rig
    tracker = EdgeTracker(seq.synth.model, rig[0])
    q = seq.poses[20]
    moved = q.copy()
    moved[0:3] += [0.03, -0.02, 0.05]
    assert fingertip_disagreement(tracker.kin, q, moved) < 1e-6
    bent = q.copy()
    bent[seq.synth.model.dof_names.index('index_mcp_flex')] += 0.3
    assert fingertip_disagreement(tracker.kin, q, bent) > 15.0


def test_cameras_that_disagree_flag_drift(rig) -> None:
    cameras, seq, frames = rig
    config = EdgeTrackerConfig(camera_check=True, camera_weights=(1.0, 1.0))
    tracker = EdgeTracker(seq.synth.model, cameras, config)
    start = seq.poses[20]
    agree = tracker.fit(frames[20], start)
    assert agree.camera_disagreement_mm < config.max_camera_disagreement_mm
    assert tracker._check_fit(agree) == ('', '')
    # the second camera's image shifted by 12 px: its edges pull the joint fit away from
    # where the first camera alone puts the hand
    shifted = [frames[20][0], np.roll(frames[20][1], 12, axis=1)]
    torn = tracker.fit(shifted, start)
    assert torn.camera_disagreement_mm > agree.camera_disagreement_mm + 5.0
    off = tracker.with_config(camera_check=False).fit(shifted, start)
    assert np.isnan(off.camera_disagreement_mm)
    kind, reason = tracker.with_config(
        max_camera_disagreement_mm=0.5 * (agree.camera_disagreement_mm
                                          + torn.camera_disagreement_mm))._check_fit(torn)
    assert kind == 'drift' and 'primary camera alone' in reason



def _backgrounds(frames) -> list:
    from colorglove_ros.core.tracking.silhouette import BackgroundModel

    return [BackgroundModel.from_frames([e]) for e in frames['empty']]



def test_a_fit_takes_its_silhouettes_around_its_own_start(rig) -> None:
    """EdgeTracker.fit from a given pose crops each silhouette around that pose, not around
    the tracker's own (here, waiting: the initialisation spot, moved far off the hand)."""
    cameras, seq, frames = rig
    far = EdgeTrackerConfig(max_unexplained=0.5, max_off_silhouette=0.5,
                            init_wrist_position=(0.4, 0.3, 0.6))
    truth = seq.poses[20]
    fit = EdgeTracker(seq.synth.model, cameras, far, _backgrounds(frames)).fit(frames[20], truth)
    assert fit.off_silhouette < 0.02 and fit.unexplained < 0.01

def test_silhouettes_measure_a_fit_that_left_the_hand(rig) -> None:
    cameras, seq, frames = rig
    # each share is measured when its check uses it (the finger re-fits, on by default, use
    # the unexplained share too: off here)
    tracker = EdgeTracker(seq.synth.model, cameras,
                          EdgeTrackerConfig(max_unexplained=0.5, max_off_silhouette=0.5,
                                            finger_refit=False),
                          _backgrounds(frames))
    truth = seq.poses[20]
    good = tracker.fit(frames[20], truth)
    assert good.off_silhouette < 0.02 and good.unexplained < 0.01
    assert np.isnan(EdgeTracker(seq.synth.model, cameras).fit(frames[20], truth).off_silhouette)
    only_share = tracker.with_config(max_off_silhouette=1.0).fit(frames[20], truth)
    assert np.isnan(only_share.off_silhouette) and only_share.unexplained == good.unexplained
    only_off = tracker.with_config(max_unexplained=1.0).fit(frames[20], truth)
    assert np.isnan(only_off.unexplained) and only_off.off_silhouette == good.off_silhouette
    # the index finger bent sideways and folded: its links leave the silhouette and its
    # true place is left unexplained
    bent = truth.copy()
    bent[seq.synth.model.dof_names.index('index_mcp_abd')] += 1.0
    bent[seq.synth.model.dof_names.index('index_mcp_flex')] += 0.8
    tracker.config = replace(tracker.config, gn_iterations=1, stabilizer=(1e9, 1e9, 1e9))
    wrong = tracker.fit(frames[20], bent)
    assert wrong.off_silhouette > 0.05 and wrong.unexplained > 0.02
    strict = tracker.with_config(max_off_silhouette=0.05, max_unexplained=0.02)
    kind, reason = strict._check_fit(wrong)
    assert kind == 'drift' and 'off the silhouette' in reason
    kind, reason = tracker.with_config(max_unexplained=0.02)._check_fit(wrong)
    assert kind == 'drift' and 'unexplained' in reason
    assert strict._check_fit(good) == ('', '')
    with pytest.raises(EdgeTrackerError):
        tracker.set_backgrounds(_backgrounds(frames)[:1])
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(max_unexplained=1.5)


def test_silhouette_residuals_pull_a_finger_back_onto_the_hand(rig) -> None:
    # the index finger bent 34 degrees too far, beyond the reach of short edge searches: the
    # edges cannot bring it back; the silhouette residuals (its axis off the hand in the side
    # camera, its true place unexplained) move it toward the silhouette
    from colorglove_ros.core.tracking.edge_features import EdgeSearchConfig

    cameras, seq, frames = rig
    truth = seq.poses[20]
    dof = seq.synth.model.dof_names.index('index_mcp_flex')
    start = truth.copy()
    start[dof] += 0.6
    fits = {}
    for weight in (0.0, 0.3):
        config = EdgeTrackerConfig(silhouette_weight=weight, max_unexplained=0.99,
                                   search=EdgeSearchConfig(search_px=2.0))
        tracker = EdgeTracker(seq.synth.model, cameras, config, _backgrounds(frames))
        fits[weight] = tracker.fit(frames[20], start, rounds=3)
    assert fits[0.3].unexplained < 0.5 * fits[0.0].unexplained


def test_digit_shares_split_the_unexplained_foreground(rig) -> None:
    """With ``finger_refit`` each fit reports, per digit, the unexplained share of the hand's
    foreground nearest to that digit: none at the true pose, most of it near the index
    finger (or its neighbour) when the index is bent off its place."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    config = EdgeTrackerConfig(finger_refit=True, gn_iterations=1,
                               stabilizer=(1e9, 1e9, 1e9))
    tracker = EdgeTracker(model, cameras, config, _backgrounds(frames))
    good = tracker.fit(frames[20], truth)
    assert max(good.finger_unexplained) < 0.005
    bent = truth.copy()
    bent[model.dof_names.index('index_mcp_abd')] += 1.0
    bent[model.dof_names.index('index_mcp_flex')] += 0.8
    wrong = tracker.fit(frames[20], bent)
    shares = np.asarray(wrong.finger_unexplained)
    assert shares.max() <= wrong.unexplained + 1e-9   # a part of one camera's share
    assert shares[1] + shares[2] > 0.01 and shares[1] + shares[2] > 0.8 * shares.sum()
    off = tracker.with_config(finger_refit=False).fit(frames[20], bent)
    assert np.all(np.isnan(off.finger_unexplained))
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(max_finger_unexplained=2.0)


def test_finger_refit_brings_a_drifted_finger_back(rig) -> None:
    """A track whose index finger drifted (bent sideways and folded) leaves its true place
    unexplained; ``finger_refit`` re-fits the finger and its neighbours from other starting
    angles and keeps the fit that explains the silhouettes better."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    bent = truth.copy()
    bent[model.dof_names.index('index_mcp_abd')] += 1.0
    bent[model.dof_names.index('index_mcp_flex')] += 0.8
    index_tip = KEYPOINT_NAMES.index('index_tip')
    errors, unexplained = {}, {}
    for on in (False, True):
        tracker = EdgeTracker(model, cameras, EdgeTrackerConfig(finger_refit=on),
                              _backgrounds(frames))
        tracker.initialize(bent)
        result = tracker.update(frames[20])
        a, b = model.keypoints(result.fit.q), model.keypoints(truth)
        errors[on] = 1e3 * np.linalg.norm((a[index_tip] - a[0]) - (b[index_tip] - b[0]))
        unexplained[on] = result.fit.unexplained
    assert errors[True] < 0.5 * errors[False]
    assert unexplained[True] < 0.5 * unexplained[False]


def test_the_defaults_refit_fingers_and_pull_the_palm_only_with_silhouettes(rig) -> None:
    """``finger_refit`` and ``silhouette_palm`` are on by default: with silhouettes the default
    tracker brings a drifted index finger back where the tracker with both off leaves it;
    without background images it tracks as the tracker with both off, pose and reason to
    the bit."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    defaults = EdgeTrackerConfig()
    assert defaults.finger_refit and defaults.silhouette_palm
    off = replace(defaults, finger_refit=False, silhouette_palm=False)
    bent = truth.copy()
    bent[model.dof_names.index('index_mcp_abd')] += 1.0
    bent[model.dof_names.index('index_mcp_flex')] += 0.8
    index_tip = KEYPOINT_NAMES.index('index_tip')
    runs = {}
    for name, config, backgrounds in (('default', defaults, _backgrounds(frames)),
                                      ('off', off, _backgrounds(frames)),
                                      ('default, edges only', defaults, None),
                                      ('off, edges only', off, None)):
        tracker = EdgeTracker(model, cameras, config, backgrounds)
        tracker.initialize(bent)
        runs[name] = [tracker.update(frames[i]) for i in (20, 21, 22)]
    errors = {}
    for name in ('default', 'off'):
        a, b = model.keypoints(runs[name][0].fit.q), model.keypoints(truth)
        errors[name] = 1e3 * np.linalg.norm((a[index_tip] - a[0]) - (b[index_tip] - b[0]))
    assert errors['default'] < 0.5 * errors['off']
    assert not np.array_equal(runs['default'][0].fit.q, runs['off'][0].fit.q)
    for mine, before in zip(runs['default, edges only'], runs['off, edges only'],
                            strict=True):
        assert mine.reason == before.reason and mine.state == before.state
        assert mine.fit.q.tobytes() == before.fit.q.tobytes()
        assert (mine.q is None) == (before.q is None)
        assert mine.q is None or mine.q.tobytes() == before.q.tobytes()


def test_palm_silhouette_targets_pull_a_displaced_hand_back(rig) -> None:
    """The whole hand 15 mm off along the palm's width, beyond short edge searches: with
    ``silhouette_palm`` the unexplained pixels nearest the palm pull the wrist back toward its
    true place; without, nothing measures the palm's place but its one side."""
    from colorglove_ros.core.tracking.edge_features import EdgeSearchConfig

    cameras, seq, frames = rig
    truth = seq.poses[20]
    start = truth.copy()
    start[0] += 0.015
    errors, unexplained = {}, {}
    for on in (False, True):
        config = EdgeTrackerConfig(silhouette_palm=on, max_unexplained=0.99,
                                   search=EdgeSearchConfig(search_px=2.0))
        tracker = EdgeTracker(seq.synth.model, cameras, config, _backgrounds(frames))
        fit = tracker.fit(frames[20], start, rounds=3)
        errors[on] = 1e3 * float(np.linalg.norm(fit.q[0:3] - truth[0:3]))
        unexplained[on] = fit.unexplained
    assert errors[True] < 0.6 * errors[False]
    assert unexplained[True] < unexplained[False]


def test_palm_targets_are_rigid_with_the_palm(rig) -> None:
    """The palm targets' weights over the palm's rigid feature points give the palm point
    itself at any pose (an affine combination of points of one rigid body)."""
    from colorglove_ros.core.tracking.kinematics import FastKinematics

    cameras, seq, _ = rig
    model = seq.synth.model
    points = feature_points(model, EdgeTrackerConfig().tracked_links, True, ('ulnar',))
    kin = FastKinematics(model)
    hull = points.palm_hull
    weights = np.hstack([hull, np.ones((len(hull), 1))]) @ points.palm_affine.T
    q = seq.poses[20]
    world = kin.points(q, points.point_link, points.point_local, False)[0]
    direct = kin.points(q, np.zeros(len(hull), np.int64), hull, False)[0]
    assert np.allclose(weights @ world[points.palm_rigid], direct, atol=1e-9)
    assert len(feature_points(model, EdgeTrackerConfig().tracked_links, True, ()).palm_affine) \
        == 0


def _with_blob_beyond_index_tip(model: HandModel, cameras, images, q: np.ndarray) -> list:
    """The images with a foreground blob drawn beyond the index fingertip of pose ``q``: it
    stays unexplained next to the index whatever the finger does."""
    import cv2

    kp = model.keypoints(q)
    ends = np.array([kp[KEYPOINT_NAMES.index('index_tip')], kp[KEYPOINT_NAMES.index('index_dip')]])
    out = []
    for cam, img in zip(cameras, images, strict=True):
        tip, dip = cam.project(cam.world_to_camera(ends))
        centre = tip + 35.0 * (tip - dip) / np.linalg.norm(tip - dip)
        img = np.array(img, copy=True)
        cv2.circle(img, tuple(int(v) for v in centre), 18, (40, 200, 40), -1)
        out.append(img)
    return out


def _count_fits(monkeypatch) -> list[int]:
    """A one-element list counting the tracker's calls of ``fit_pose`` from now on."""
    from colorglove_ros.core.tracking import edge_tracker

    calls = [0]
    fit_pose = edge_tracker.fit_pose

    def counting(*args, **kwargs):
        calls[0] += 1
        return fit_pose(*args, **kwargs)

    monkeypatch.setattr(edge_tracker, 'fit_pose', counting)
    return calls


def test_a_finger_refit_that_fails_backs_off(rig, monkeypatch) -> None:
    """A digit its re-fit leaves unexplained (a blob beyond the index tip no finger pose
    explains) is re-fitted again only after ``finger_refit_backoff`` frames, then after twice
    as many; without the back-off every frame re-fits it. The failed re-fits change nothing,
    so the poses are the same either way."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    images = _with_blob_beyond_index_tip(model, cameras, frames[20], truth)
    calls = _count_fits(monkeypatch)
    fits, poses = {}, {}
    for backoff in (0, 1):
        # (the palm's pull, on by default, off: it moves the hand toward the blob too; the
        # fault round off: the frame's own fit is one call)
        tracker = EdgeTracker(model, cameras, EdgeTrackerConfig(
            finger_refit=True, silhouette_palm=False, finger_refit_backoff=backoff,
            loss_patience=10, fault_round=False),
            _backgrounds(frames))
        tracker.initialize(truth)
        fits[backoff], poses[backoff] = [], []
        for _ in range(6):
            calls[0] = 0
            result = tracker.update(images)
            fits[backoff].append(calls[0])
            poses[backoff].append(result.fit.q)
    assert all(n > 1 for n in fits[0])                  # re-fits on every frame
    assert fits[1][0] > 1 and fits[1][1] == 1           # fails, waits one frame,
    assert fits[1][2] > 1 and fits[1][3] == fits[1][4] == 1   # fails again, waits two
    assert fits[1][5] > 1
    assert np.allclose(poses[0], poses[1])
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(finger_refit_backoff=4, finger_refit_max_wait=2)


def test_the_finger_refit_budget_bounds_the_refits(rig, monkeypatch) -> None:
    """With ``finger_refit_budget`` the re-fit candidates over N frames are at most
    ``finger_refit_burst`` + budget x N, however many digits stay unexplained."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    images = _with_blob_beyond_index_tip(model, cameras, frames[20], truth)
    calls = _count_fits(monkeypatch)
    candidates = {}
    for budget in (0.0, 0.5):
        tracker = EdgeTracker(model, cameras, EdgeTrackerConfig(
            finger_refit=True, finger_refit_budget=budget, finger_refit_burst=2,
            loss_patience=10, fault_round=False), _backgrounds(frames))
        tracker.initialize(truth)
        calls[0] = 0
        for _ in range(5):
            tracker.update(images)
        candidates[budget] = calls[0] - 5          # one fit per frame is the frame's own
    assert candidates[0.0] >= 10
    assert 0 < candidates[0.5] <= 2 + 0.5 * 5
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(finger_refit_budget=-1.0)


def test_even_subsample_spreads_at_most_count_indices() -> None:
    from colorglove_ros.core.tracking.edge_fit import even_subsample

    assert even_subsample(4, 10).tolist() == [0, 1, 2, 3]
    assert even_subsample(10, 4).tolist() == [0, 3, 6, 9]
    assert even_subsample(10, 0).tolist() == [] and even_subsample(0, 3).tolist() == []
    assert even_subsample(1000, 7).dtype == np.int64


def test_a_finger_off_its_silhouette_is_withheld(rig) -> None:
    """A fit whose index finger lies off the silhouette (bent sideways onto the background)
    while the rest of the hand explains its edges gives no pose with
    ``max_finger_off_silhouette`` set, keeps the track and says which finger; the true pose
    is published, and without the gate the bent one is too."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    bent = truth.copy()
    bent[model.dof_names.index('index_mcp_abd')] += 0.5
    frozen = dict(gn_iterations=1, stabilizer=(1e9, 1e9, 1e9), max_unexplained=1.0)
    results = {}
    for name, gate, q in (('bent', 0.15, bent), ('true', 0.15, truth), ('off', 1.0, bent)):
        tracker = EdgeTracker(model, cameras, EdgeTrackerConfig(
            max_finger_off_silhouette=gate, **frozen), _backgrounds(frames))
        tracker.initialize(q)
        results[name] = tracker.update(frames[20])
    bent_fit = results['bent'].fit
    assert bent_fit.finger_off_silhouette[1] > 0.15
    assert results['bent'].q is None and results['bent'].state == 'tracking'
    assert results['bent'].reason.startswith('finger withheld: index finger')
    assert max(results['true'].fit.finger_off_silhouette[1:]) <= 0.15
    assert results['true'].q is not None and results['off'].q is not None
    assert np.all(np.isnan(results['off'].fit.finger_off_silhouette))


def test_a_thumb_click_faster_than_the_edge_search_is_found_by_the_retry() -> None:
    """The 3-D mouse's table view: the thumb abducted 35 degrees since the last pose, out of
    reach of the edge search; without ``retry_dofs`` the fit leaves it at rest (or fails),
    with the thumb's abduction retried from farther starts it is found; its counts per digit
    say the thumb's links were missing."""
    from colorglove_ros.core.tracking.mouse import MouseConfig
    from colorglove_ros.tools.eval_mouse import scripted_sequence

    calibration = load_calibration(resolve_path('config/calibration.yaml'))
    model = HandModel(calibration.hand_length_m)
    Q, spans = scripted_sequence(model, MouseConfig(), seed=5, seconds=3.0, clicks=1)
    start, _ = spans[0][0]
    frame = start + 6
    seq = BareHandSequence(calibration.cameras[0], seed=5, poses=Q,
                           hand_length_m=calibration.hand_length_m)
    try:
        image = [seq.render_views(frame, calibration.cameras[:1])[0].image_rgb]
    finally:
        seq.close()
    thumb = model.dof_names.index('thumb_cmc_abd')
    before = Q[frame].copy()
    before[thumb] = Q[start - 1, thumb]
    errors = {}
    # the last setting: a guard no candidate passes (the wrist must stay within 10 um)
    for name, retry, guard in (('off', (), {}), ('on', ('thumb_cmc_abd',), {}),
                               ('guarded', ('thumb_cmc_abd',), {'retry_max_wrist_move_m': 1e-5})):
        tracker = EdgeTracker(model, calibration.cameras[:1],
                              EdgeTrackerConfig(loss_patience=1, retry_dofs=retry, **guard))
        tracker.initialize(before)
        out = tracker.update(image)
        q = out.q if out.q is not None else before
        errors[name] = abs(np.degrees(q[thumb] - Q[frame, thumb]))
        if name == 'on':
            assert out.q is not None, out.reason
            assert out.fit.digit_links_found[0] == out.fit.digit_links_usable[0] > 0
    assert errors['off'] > 25.0 and errors['on'] < 5.0 and errors['guarded'] > 25.0
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(retry_dofs=('thumb_abduction',))


def _fit(q: np.ndarray, rms: float, found: int, thumb_found: int) -> EdgeFit:
    return EdgeFit(q, rms, (found,), (20,), (5,), 3, digit_links_found=(thumb_found, 4, 4, 4, 4),
                   digit_links_usable=(3, 4, 4, 4, 4))


def test_the_retry_guards_keep_a_candidate_only_when_the_rest_of_the_hand_stays() -> None:
    """A retried candidate must keep the wrist near the previous pose and, once a frame was
    good, find as many links outside the retried digit as that frame's fit with a residual
    at most the margin above its."""
    calibration = load_calibration(resolve_path('config/calibration.yaml'))
    model = HandModel(calibration.hand_length_m)
    q = initialisation_pose(model, (0.0, 0.05, 0.5))
    tracker = EdgeTracker(model, calibration.cameras[:1], EdgeTrackerConfig(
        retry_dofs=('thumb_cmc_abd',), retry_max_wrist_move_m=0.01, retry_rest_margin_px=0.5))
    tracker.initialize(q)
    near, far = q.copy(), q.copy()
    near[0] += 0.005
    far[0] += 0.02
    # no good frame yet: only the wrist is checked
    assert tracker._retry_guard(_fit(near, 2.9, 17, 3), 0)
    assert not tracker._retry_guard(_fit(far, 1.0, 20, 3), 0)
    tracker._last_good = _fit(q, 1.0, 17, 1)           # 16 links outside the thumb
    assert tracker._retry_guard(_fit(near, 1.5, 19, 3), 0)
    assert not tracker._retry_guard(_fit(near, 1.6, 19, 3), 0)    # residual 0.6 px above
    assert not tracker._retry_guard(_fit(near, 1.0, 18, 3), 0)    # 15 links outside the thumb
    off = EdgeTracker(model, calibration.cameras[:1], EdgeTrackerConfig(
        retry_dofs=('thumb_cmc_abd',)))
    off.initialize(q)
    off._last_good = tracker._last_good
    assert off._retry_guard(_fit(far, 2.9, 5, 3), 0)              # both guards off (inf)
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(retry_max_wrist_move_m=0.0)
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(retry_rest_margin_px=-1.0)


def test_a_fit_leaves_the_held_dofs_at_their_start(rig) -> None:
    """``fit_pose(held=...)`` fits the other DOFs and leaves the held ones where they
    started: a perturbed pose with the index finger's abduction held pulls the rest back
    (here the index flexion) and keeps that abduction to the bit."""
    from colorglove_ros.core.tracking.edge_fit import fit_pose

    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    tracker = EdgeTracker(model, cameras)
    abd, flex = (model.dof_names.index(n) for n in ('index_mcp_abd', 'index_mcp_flex'))
    start = truth.copy()
    start[abd] += 0.1
    start[flex] += 0.15
    held = np.zeros(len(truth), dtype=bool)
    held[abd] = True
    greys = tracker._greys(frames[20])
    fit = fit_pose(tracker.kin, tracker.points, cameras, greys, start, tracker.config, 3,
                   held=held)
    free = fit_pose(tracker.kin, tracker.points, cameras, greys, start, tracker.config, 3)
    assert fit.q[abd] == tracker.kin.clamp(start)[abd]
    assert abs(free.q[abd] - start[abd]) > 1e-3          # unheld, the abduction moves
    assert abs(fit.q[flex] - truth[flex]) < 0.5 * abs(start[flex] - truth[flex])
    with pytest.raises(EdgeTrackerError):
        fit_pose(tracker.kin, tracker.points, cameras, greys, start, tracker.config, 1,
                 held=held[:5])


def _refit_calls(monkeypatch) -> list[tuple[np.ndarray, np.ndarray | None, np.ndarray]]:
    """(start pose, held DOFs, fitted pose) of every ``fit_pose`` call of the tracker from
    now on."""
    from colorglove_ros.core.tracking import edge_tracker

    calls: list[tuple[np.ndarray, np.ndarray | None, np.ndarray]] = []
    fit_pose = edge_tracker.fit_pose

    def recording(*args, **kwargs):
        fit = fit_pose(*args, **kwargs)
        calls.append((np.array(args[4]), kwargs.get('held'), fit.q.copy()))
        return fit

    monkeypatch.setattr(edge_tracker, 'fit_pose', recording)
    return calls


@pytest.mark.parametrize('dofs, abduction', [('hand', 'start'), ('hand', 'kept'),
                                             ('hand', 'both'), ('hand', 'spread'),
                                             ('abduction', 'start'), ('digit', 'start'),
                                             ('flexion', 'start')])
def test_finger_refit_candidates_start_and_hold_as_configured(rig, monkeypatch, dofs: str,
                                                               abduction: str) -> None:
    """The index finger left unexplained (a blob beyond its tip): its re-fit candidates
    start from the frame's fit with the index's angles of the last frame where it was
    explained and the initialisation pose's, their abduction as ``finger_refit_abduction``
    says (kept at the frame's fit; 'spread': also moved ``finger_refit_spread_deg`` out and
    in), and fit what ``finger_refit_dofs`` says, the rest held where they start."""
    cameras, seq, frames = rig
    model, truth = seq.synth.model, seq.poses[20]
    images = _with_blob_beyond_index_tip(model, cameras, frames[20], truth)
    config = EdgeTrackerConfig(finger_refit=True, loss_patience=10, finger_refit_dofs=dofs,
                               finger_refit_abduction=abduction, finger_refit_spread_deg=5.0)
    tracker = EdgeTracker(model, cameras, config, _backgrounds(frames))
    tracker.initialize(truth)
    first = tracker.update(frames[20])
    assert max(first.fit.finger_unexplained) <= config.max_finger_unexplained   # no re-fit
    index = tracker._digit_dofs[1]
    good = first.fit.q[index]                         # the index's explained angles
    calls = _refit_calls(monkeypatch)
    tracker.update(images)
    _, _, frame_q = calls[0]                          # the frame's own fit
    init = tracker.init_pose[index]
    kept, step = frame_q[index[0]], np.radians(5.0)
    out, inward = (float(np.clip(kept + s * step, tracker.kin.lower[index[0]],
                                 tracker.kin.upper[index[0]])) for s in (1.0, -1.0))
    expected = {
        'start': [good, init],
        'kept': [np.r_[kept, good[1:]], np.r_[kept, init[1:]]],
        'both': [np.r_[kept, good[1:]], good, np.r_[kept, init[1:]], init],
        'spread': [np.r_[kept, good[1:]], *(np.r_[a, good[1:]] for a in (out, inward)
                                             if a != kept),      # none past the limit
                   np.r_[kept, init[1:]]],
    }['kept' if dofs in ('abduction', 'flexion') else abduction]
    candidates = calls[1:1 + len(expected)]           # the index re-fitted first
    assert len(candidates) == len(expected)
    want = np.zeros(len(truth), dtype=bool)
    if dofs == 'abduction':
        want[index[0]] = True
    elif dofs in ('digit', 'flexion'):
        want[:] = True
        want[index[1:] if dofs == 'flexion' else index] = False
    others = np.setdiff1d(np.arange(len(truth)), index)
    for (start, held, fitted), angles in zip(candidates, expected, strict=True):
        assert np.array_equal(start[index], angles)
        assert np.array_equal(start[others], frame_q[others])
        assert np.array_equal(np.zeros(len(truth), bool) if held is None else held, want)
        assert np.array_equal(fitted[want], tracker.kin.clamp(start)[want])
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(finger_refit_dofs='wrist')
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(finger_refit_abduction='out')


def _frame_21_from_a_moved_start(rig):
    """What a fit of frame 21 needs, from frame 20's pose with the index flexed 0.25 rad more
    and the wrist 6 mm off: (kin, points, cameras, greys, start, default config)."""
    from colorglove_ros.core.tracking.kinematics import FastKinematics

    cameras, seq, frames = rig
    model, config = seq.synth.model, EdgeTrackerConfig()
    points = feature_points(model, config.tracked_links, config.use_tips, config.palm_sides)
    start = seq.poses[20].copy()
    start[model.dof_names.index('index_mcp_flex')] += 0.25
    start[0] += 0.006
    return (FastKinematics(model), points, cameras, [to_grey(f) for f in frames[21]], start,
            config)


def test_a_fit_continued_with_its_start_as_anchor_is_one_more_round(rig) -> None:
    """``fit_pose(anchor=...)``: one round from a 1-round fit's pose, anchored at that fit's
    start, lands where a 2-round fit does; anchored at its own start it does not."""
    from colorglove_ros.core.tracking.edge_fit import fit_pose

    kin, points, cameras, greys, start, config = _frame_21_from_a_moved_start(rig)
    two = fit_pose(kin, points, cameras, greys, start, config, 2)
    one = fit_pose(kin, points, cameras, greys, start, config, 1)
    assert not np.allclose(one.q, two.q)
    more = fit_pose(kin, points, cameras, greys, one.q, config, 1, anchor=start)
    assert np.allclose(more.q, two.q, atol=1e-12) and more.rms_px == pytest.approx(two.rms_px)
    own = fit_pose(kin, points, cameras, greys, one.q, config, 1)
    assert not np.allclose(own.q, two.q)


def _fit_calls(monkeypatch) -> list[tuple[np.ndarray, int, np.ndarray | None, EdgeFit]]:
    """The tracker's ``fit_pose`` calls from now on: (start, rounds, anchor, fit)."""
    from colorglove_ros.core.tracking import edge_tracker

    calls: list[tuple[np.ndarray, int, np.ndarray | None, EdgeFit]] = []
    fit_pose = edge_tracker.fit_pose

    def recording(kin, points, cameras, greys, q_start, config, rounds, **kwargs):
        fit = fit_pose(kin, points, cameras, greys, q_start, config, rounds, **kwargs)
        anchor = kwargs.get('anchor')
        calls.append((np.array(q_start), rounds, None if anchor is None else np.array(anchor),
                      fit))
        return fit

    monkeypatch.setattr(edge_tracker, 'fit_pose', recording)
    return calls


@pytest.mark.parametrize('fault_round', [True, False])
def test_the_fault_round_measures_a_faulted_fit_again(rig, monkeypatch,
                                                      fault_round: bool) -> None:
    """``fault_round``: a tracked frame whose fit fails a check is measured and fitted once
    more from that fit's pose, anchored at the previous pose, and the second fit is the one
    checked (a fit still poor publishes nothing); a frame whose fit passes gets one fit."""
    cameras, seq, frames = rig
    config = EdgeTrackerConfig(fault_round=fault_round, finger_refit=False, loss_patience=5)
    calls = _fit_calls(monkeypatch)
    tracker = EdgeTracker(seq.synth.model, cameras, config)
    tracker.initialize(seq.poses[20])
    good = tracker.update(frames[21])
    assert good.q is not None and len(calls) == 1 and tracker.fault_rounds == 0
    previous = good.q
    calls.clear()
    # the second camera sees nothing: the first fit finds too few of its links
    half_blind = [frames[22][0], np.full_like(frames[22][1], 90)]
    out = tracker.update(half_blind)
    assert tracker._check_fit(calls[0][3])[0] == 'coverage'
    assert out.q is None and out.reason.startswith('poor fit') and not out.lost
    assert 0.0 < out.thread_cpu_ms <= out.cpu_ms + 1.0     # the tracker's own thread
    if not fault_round:
        assert len(calls) == 1 and tracker.fault_rounds == 0
        return
    assert len(calls) == 2 and tracker.fault_rounds == 1
    (start0, _, anchor0, first), (start1, rounds1, anchor1, second) = calls
    assert np.allclose(start0, previous) and anchor0 is None
    assert np.allclose(start1, first.q) and rounds1 == 1 and np.allclose(anchor1, previous)
    assert out.fit is second and np.allclose(tracker.pose, second.q)


def test_the_defaults_measure_twice_retry_faults_and_let_one_link_of_ten_pass(rig) -> None:
    """The defaults: two measurement rounds, the fault round, and a camera that finds one of
    up to ten of its usable links (the 45-degree camera, the primary finding all of its own)
    passes the per-camera coverage check; one that finds none does not."""
    cameras, seq, _ = rig
    config = EdgeTrackerConfig()
    assert config.measurement_rounds == 2 and config.fault_round
    tracker = EdgeTracker(seq.synth.model, cameras, config)
    q = seq.poses[20]
    assert tracker._check_fit(EdgeFit(q, 1.0, (14, 1), (14, 8), (5, 1), 3)) == ('', '')
    assert tracker._check_fit(EdgeFit(q, 1.0, (14, 1), (14, 11), (5, 1), 3))[0] == 'coverage'
    assert tracker._check_fit(EdgeFit(q, 1.0, (14, 0), (14, 5), (5, 1), 3))[0] == 'coverage'


def test_a_round_that_barely_moved_ends_the_fit(rig) -> None:
    """``round_min_move_px``: a 2-round fit whose first round moved no feature point by more
    than it is the 1-round fit, exactly; one whose first round moved more makes the second
    round."""
    from colorglove_ros.core.tracking.edge_fit import _largest_move_px, fit_pose

    kin, points, cameras, greys, start, config = _frame_21_from_a_moved_start(rig)
    one = fit_pose(kin, points, cameras, greys, start, config, 1)
    two = fit_pose(kin, points, cameras, greys, start, config, 2)
    assert not np.allclose(one.q, two.q) and two.iterations == 2 * config.gn_iterations
    world = [kin.points(q, points.point_link, points.point_local, False)[0]
             for q in (kin.clamp(start), one.q)]
    moved = _largest_move_px(cameras, greys, *world)
    assert moved > 1.0
    stopped = fit_pose(kin, points, cameras, greys, start,
                       replace(config, round_min_move_px=moved + 0.01), 2)
    assert np.array_equal(stopped.q, one.q) and stopped.rms_px == one.rms_px
    assert stopped.links_found == one.links_found and stopped.iterations == one.iterations
    kept = fit_pose(kin, points, cameras, greys, start,
                    replace(config, round_min_move_px=moved - 0.01), 2)
    assert np.array_equal(kept.q, two.q) and kept.rms_px == two.rms_px
    # the move is counted only in cameras with an image
    assert _largest_move_px(cameras, [greys[0], None], *world) <= moved
    with pytest.raises(EdgeTrackerError):
        EdgeTrackerConfig(round_min_move_px=-1.0)


def test_the_initialisation_makes_all_its_rounds_whatever_the_round_gate(rig,
                                                                         monkeypatch) -> None:
    """With ``round_min_move_px`` set, the initialisation's fit (from the documented pose,
    far from the hand) still makes every one of its ``init_rounds``; a tracked frame's fit
    is gated."""
    from colorglove_ros.core.tracking import edge_tracker

    cameras, seq, frames = rig
    seen: list[tuple[int, float]] = []
    fit_pose = edge_tracker.fit_pose

    def recording(kin, points, cameras, greys, q_start, config, rounds, **kwargs):
        seen.append((rounds, config.round_min_move_px))
        return fit_pose(kin, points, cameras, greys, q_start, config, rounds, **kwargs)

    monkeypatch.setattr(edge_tracker, 'fit_pose', recording)
    config = EdgeTrackerConfig(round_min_move_px=1e6, finger_refit=False, fault_round=False)
    tracker = EdgeTracker(seq.synth.model, cameras, config)
    tracker.update(frames[0])                        # waiting: the initialisation's fit
    assert seen == [(config.init_rounds, 0.0)]
    tracker.initialize(seq.poses[20])
    tracker.update(frames[21])
    assert seen[1:] == [(config.measurement_rounds, 1e6)]
