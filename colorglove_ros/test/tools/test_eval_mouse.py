"""colorglove_eval_mouse: the mouse scored on given pose streams (true, noisy, none, tracked)."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.tracking.edge_fit import EdgeTrackerConfig
from colorglove_ros.core.tracking.mouse import BUTTON_DOFS, MouseConfig, raw_mouse_values
from colorglove_ros.paths import resolve_path
from colorglove_ros.tools.eval_mouse import (
    edge_tracked_poses,
    evaluate_seed,
    glove_tracked_poses,
    noisy_poses,
    reinitialisation_pose,
    scripted_sequence,
    track_scripted,
)
from colorglove_ros.tools.eval_mouse import (
    main as eval_mouse_main,
)

MODEL = HandModel()
CONFIG = MouseConfig()


def test_true_poses_detect_every_scripted_click_and_no_pose_detects_none() -> None:
    Q, spans = scripted_sequence(MODEL, CONFIG, seed=3, seconds=12.0, clicks=4)
    perfect = evaluate_seed(MODEL, CONFIG, 3, list(Q), 0, Q, spans)
    assert perfect['scripted_clicks'] == 8 and perfect['correct'] == 8
    assert perfect['precision'] == 1.0 and perfect['recall'] == 1.0
    assert perfect['cursor_error_mm'] < 5.0            # only the smoothing's lag
    assert perfect['correct_at_reinit'] == 0
    blind = evaluate_seed(MODEL, CONFIG, 3, [None] * len(Q), 0, Q, spans)
    assert blind['detected'] == 0 and blind['recall'] == 0.0
    assert math.isnan(blind['cursor_error_mm'])


def test_each_missed_click_and_false_press_is_listed_by_button_and_frame() -> None:
    Q, spans = scripted_sequence(MODEL, CONFIG, seed=3, seconds=12.0, clicks=4)
    poses = list(Q)
    a, b = spans[1][2]                      # the third little click never seen
    for i in range(a, b):
        poses[i] = None
    rest_end = spans[0][0][0] - 10          # a thumb click where there is none
    fake = np.array(Q[rest_end - 15])
    fake[MODEL.dof_names.index('thumb_cmc_abd')] = math.radians(40.0)
    poses[rest_end - 15:rest_end] = [fake] * 15
    row = evaluate_seed(MODEL, CONFIG, 3, poses, 0, Q, spans)
    assert row['missed_clicks'] == [('little', a, b)]
    assert len(row['false_presses']) == 1
    button, frame = row['false_presses'][0]
    assert button == 'thumb' and rest_end - 15 <= frame < rest_end
    assert row['correct'] == 7 and row['detected'] == 8
    perfect = evaluate_seed(MODEL, CONFIG, 3, list(Q), 0, Q, spans)
    assert perfect['missed_clicks'] == [] and perfect['false_presses'] == []


def test_clicks_with_a_reinitialisation_from_the_truth_before_the_press_are_counted() -> None:
    Q, spans = scripted_sequence(MODEL, CONFIG, seed=3, seconds=12.0, clicks=4)
    (a, _), (c, _) = spans[0][2], spans[0][3]
    gap = (spans[0][2][1] + c) // 2
    assert all(not s <= gap < e for s, e in spans[1])
    row = evaluate_seed(MODEL, CONFIG, 3, list(Q), 0, Q, spans, reinitialised=[0, a, gap])
    # the third click's start counts (the press comes after it); a frame before any click
    # or between clicks does not
    assert row['correct'] == 8 and row['correct_at_reinit'] == 1


def test_the_mouse_holds_presses_back_on_the_frames_of_a_poor_fit() -> None:
    Q, spans = scripted_sequence(MODEL, CONFIG, seed=3, seconds=12.0, clicks=4)
    a, b = spans[0][1]
    residuals = np.ones(len(Q))
    residuals[a:b] = 4.0                      # the second thumb click seen by a poor fit
    gated = replace(CONFIG, press_max_residual_ratio=2.0)
    row = evaluate_seed(MODEL, gated, 3, list(Q), 0, Q, spans, residuals=list(residuals))
    assert row['correct'] == 7 and row['detected'] == 7
    assert evaluate_seed(MODEL, CONFIG, 3, list(Q), 0, Q, spans,
                         residuals=list(residuals))['correct'] == 8
    assert evaluate_seed(MODEL, gated, 3, list(Q), 0, Q, spans)['correct'] == 8


class _FakeEdgeTracker:
    """Stands in for EdgeTracker: records its initialisations, publishes the pose it was
    given and loses the hand at the frames in ``lose_at``."""

    def __init__(self, lose_at: set[int]) -> None:
        self.lose_at, self.frame, self.starts = lose_at, 0, []
        self.state = 'waiting'

    def initialize(self, q: np.ndarray) -> None:
        self.starts.append((self.frame, q.copy()))
        self.q, self.state = q.copy(), 'tracking'

    def update(self, images):
        assert images == ['frame', self.frame]
        lost = self.frame in self.lose_at
        self.state = 'waiting' if lost else 'tracking'
        self.frame += 1
        return type('Result', (), {'q': None if lost else self.q.copy()})()


def test_a_reinitialisation_during_a_click_does_not_hand_the_tracker_the_click() -> None:
    Q, spans = scripted_sequence(MODEL, CONFIG, seed=3, seconds=12.0, clicks=4)
    (a, b), (c, d) = spans[0][1], spans[1][2]
    top_thumb, top_little = (a + b) // 2, (c + d) // 2
    views = lambda i: ['frame', i]  # noqa: E731
    starts = {}
    for reinit in ('rest', 'truth'):
        tracker = _FakeEdgeTracker({top_thumb - 1, top_little - 1})
        poses, restarts = track_scripted(tracker, Q, views, reinit)
        assert restarts == [top_thumb, top_little] and len(poses) == len(Q)
        starts[reinit] = dict(tracker.starts)
        row = evaluate_seed(MODEL, CONFIG, 3, [r.q for r in poses], 0, Q, spans, restarts)
        starts[reinit]['clicks'] = row['correct']
    # the truth at the top of a click presses the button; the same pose with the buttons'
    # joints at rest presses none, and keeps every other joint true
    for frame, button, joint in ((top_thumb, 3, 'thumb_cmc_abd'),
                                 (top_little, 4, 'little_mcp_abd')):
        assert raw_mouse_values(MODEL, starts['truth'][frame], CONFIG)[button] \
            > CONFIG.press_deg[button - 3]
        rest = raw_mouse_values(MODEL, starts['rest'][frame], CONFIG)
        assert rest[3] < CONFIG.release_deg[0] and rest[4] < CONFIG.release_deg[1]
        assert np.array_equal(starts['truth'][frame], Q[frame])
        moved = np.flatnonzero(starts['rest'][frame] != Q[frame])
        moved_names = {MODEL.dof_names[i] for i in moved}
        assert joint in moved_names and moved_names <= set(BUTTON_DOFS)
    # a tracker that only repeats its start makes no click from a rest start
    assert starts['rest']['clicks'] == 0 and starts['truth']['clicks'] == 2
    assert np.array_equal(reinitialisation_pose(Q[0]), Q[0])      # the script starts at rest


def test_noise_model_drops_frames_and_perturbs_the_rest() -> None:
    Q, _ = scripted_sequence(MODEL, CONFIG, seed=1, seconds=4.0, clicks=2)
    noise = {'joint_deg': 3.0, 'position_mm': 3.0, 'rotation_deg': 1.5, 'drop': 0.2}
    poses = noisy_poses(MODEL, Q, 1, noise)
    kept = [(p, q) for p, q in zip(poses, Q, strict=True) if p is not None]
    assert 0.6 * len(Q) < len(kept) < len(Q)
    err = np.degrees(np.abs(np.stack([p[6:] - q[6:] for p, q in kept])))
    assert 1.0 < err.mean() < 4.0
    assert all(np.array_equal(a, b) for a, b in zip(poses, noisy_poses(MODEL, Q, 1, noise),
                                                    strict=True) if a is not None)


@pytest.mark.slow
def test_edge_tracker_output_is_one_pose_or_none_per_frame() -> None:
    calibration = load_calibration(resolve_path('config/calibration.yaml'))
    Q, _ = scripted_sequence(MODEL, CONFIG, seed=0, seconds=3.0, clicks=1)
    runs = {sil: edge_tracked_poses(Q, 0, calibration.cameras[:1], calibration.hand_length_m,
                                    silhouettes=sil) for sil in (False, True)}
    for poses, restarts, residuals in runs.values():
        assert len(poses) == len(Q) and all(0 <= i < len(Q) for i in restarts)
        assert len(residuals) == len(Q)
        assert all(r > 0 for p, r in zip(poses, residuals, strict=True) if p is not None)
        assert all(p is None or (p.shape == (26,) and np.all(np.isfinite(p))) for p in poses)
    # the silhouettes of the empty table scene reach the tracker and change its fits
    assert any((a is None) != (b is None) or (a is not None and not np.allclose(a, b))
               for a, b in zip(runs[False][0], runs[True][0], strict=True))


@pytest.mark.slow
def test_edge_tracker_fits_the_second_table_camera_when_asked() -> None:
    calibration = load_calibration(resolve_path('config/calibration_table_stereo.yaml'))
    Q, _ = scripted_sequence(MODEL, CONFIG, seed=0, seconds=2.5, clicks=1)
    one, _, _ = edge_tracked_poses(Q, 0, calibration.cameras[:1], calibration.hand_length_m)
    two, restarts, _ = edge_tracked_poses(Q, 0, calibration.cameras[:2], calibration.hand_length_m)
    assert len(two) == len(Q) and all(0 <= i < len(Q) for i in restarts)
    assert all(p is None or (p.shape == (26,) and np.all(np.isfinite(p))) for p in two)
    # the front camera's edges change the fits
    assert any((a is None) != (b is None) or (a is not None and not np.allclose(a, b))
               for a, b in zip(one, two, strict=True))


@pytest.mark.parametrize('flags, on', [([], True), (['--finger-refit', '--silhouette-palm'], True),
                                       (['--no-finger-refit', '--no-silhouette-palm'], False)])
def test_the_edge_trackers_refits_and_palm_pull_are_on_unless_turned_off(
        tmp_path, flags: list[str], on: bool) -> None:
    out = tmp_path / 'mouse.json'
    assert eval_mouse_main(['--source', 'noise', '--seeds', '0', '--seconds', '2', *flags,
                            '--json', str(out)]) == 0
    settings = json.loads(out.read_text())['settings']
    assert settings['finger_refit'] is on and settings['silhouette_palm'] is on


def test_two_cameras_need_a_calibration_with_two() -> None:
    code = eval_mouse_main(['--source', 'edges', '--cameras', '2', '--seeds', '0',
                            '--seconds', '1', '--calibration', 'config/calibration.yaml'])
    assert code != 0


class _FakeGloveTracker:
    """Stands in for ScriptedTracker: returns the truth, every third frame not found."""

    def observe(self, name, seed, truth, model):
        self.seen = (name, seed, truth.poses.shape, truth.fps)
        found = np.arange(len(truth.poses)) % 3 != 0
        return np.where(found[:, None], truth.poses, np.nan), found


def test_glove_tracker_output_reaches_the_mouse_with_gaps_where_it_found_no_hand() -> None:
    Q, spans = scripted_sequence(MODEL, CONFIG, seed=2, seconds=6.0, clicks=2)
    fake = _FakeGloveTracker()
    poses = glove_tracked_poses(MODEL, Q, 2, fake)
    assert fake.seen == ('mouse', 2, Q.shape, 30.0)
    assert [p is None for p in poses] == [i % 3 == 0 for i in range(len(Q))]
    assert all(np.array_equal(p, q) for p, q in zip(poses, Q, strict=True) if p is not None)
    row = evaluate_seed(MODEL, CONFIG, 2, poses, 3, Q, spans)
    assert row['frames_with_pose'] == len(Q) - len(range(0, len(Q), 3))


@pytest.mark.parametrize('flags, rounds, fault, camera', [
    ([], EdgeTrackerConfig.measurement_rounds, EdgeTrackerConfig.fault_round,
     EdgeTrackerConfig.min_camera_found_fraction),
    (['--measurement-rounds', '1', '--no-fault-round', '--min-camera-found-fraction', '0.25'],
     1, False, 0.25),
    (['--measurement-rounds', '3', '--fault-round', '--min-camera-found-fraction', '0.1'],
     3, True, 0.1)])
def test_the_edge_trackers_rounds_reach_its_settings(tmp_path, flags: list[str], rounds: int,
                                                     fault: bool, camera: float) -> None:
    out = tmp_path / 'mouse.json'
    assert eval_mouse_main(['--source', 'noise', '--seeds', '0', '--seconds', '2', *flags,
                            '--json', str(out)]) == 0
    settings = json.loads(out.read_text())['settings']
    assert settings['measurement_rounds'] == rounds and settings['fault_round'] is fault
    assert settings['min_camera_found_fraction'] == camera


def test_the_edge_trackers_refit_settings_and_round_gate_reach_its_settings(tmp_path) -> None:
    out = tmp_path / 'mouse.json'
    assert eval_mouse_main(['--source', 'noise', '--seeds', '0', '--seconds', '2',
                            '--finger-refit-dofs', 'abduction', '--finger-refit-abduction',
                            'both', '--finger-refit-spread-deg', '6', '--round-min-move-px',
                            '3', '--json', str(out)]) == 0
    settings = json.loads(out.read_text())['settings']
    assert (settings['finger_refit_dofs'], settings['finger_refit_abduction'],
            settings['finger_refit_spread_deg'], settings['round_min_move_px']) \
        == ('abduction', 'both', 6.0, 3.0)


def test_the_tool_runs_opencv_as_the_node_does(tmp_path) -> None:
    """OpenCV's threads default to the nodes' ``opencv_threads``; ``--opencv-threads`` sets it."""
    import cv2

    from colorglove_ros.core.opencv_threads import OPENCV_THREADS

    before = cv2.getNumThreads()
    try:
        for flags, threads in (([], OPENCV_THREADS), (['--opencv-threads', '2'], 2)):
            cv2.setNumThreads(3)
            out = tmp_path / 'mouse.json'
            assert eval_mouse_main(['--source', 'noise', '--seeds', '0', '--seconds', '2',
                                    *flags, '--json', str(out)]) == 0
            assert cv2.getNumThreads() == threads
            assert json.loads(out.read_text())['settings']['opencv_threads'] == threads
    finally:
        cv2.setNumThreads(before)
