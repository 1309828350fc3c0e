"""The real-scene ladder (core/evaluation/scenes.py, tools/eval_scenes.py): every rung runs the
whole recipe on rendered RGB frames, classes frames from the ground truth and prints and writes
the same figures; a hand entering across a border is never published from the crop alone."""
from __future__ import annotations

import json

import numpy as np

from colorglove_ros.core.evaluation.machine_speed import MACHINE_SPEED_TITLE
from colorglove_ros.core.evaluation.scenes import (
    NO_HAND_TAIL_FRACTION,
    SCENE_LADDER,
    fully_visible,
    scene_poses,
    varied_finger_factors,
)
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.core.synthetic.sequences import BORDERS, border_crossing_sequence
from colorglove_ros.tools import eval_scenes


def test_border_crossings_visit_every_border_and_leave_the_view(hand) -> None:
    camera = default_camera()
    model = hand[0]
    seen = set()
    for seed in range(4):
        poses, entered = border_crossing_sequence(seed, 150, camera=camera, model=model)
        seen.update(entered)
        inside = []
        for q in poses:
            uv = camera.project(model.keypoints(q))
            inside.append(np.mean((uv[:, 0] >= 0) & (uv[:, 0] < 640) & (uv[:, 1] >= 0)
                                  & (uv[:, 1] < 480)))
        inside = np.array(inside)
        assert inside[0] == 0.0 and (inside == 1.0).any()
        assert ((inside > 0) & (inside < 1)).any()       # partly visible on the way in/out
    assert seen == set(BORDERS)


def test_scene_poses_end_without_a_hand_and_proportions_vary(hand) -> None:
    camera = default_camera()
    poses = scene_poses(SCENE_LADDER[0], 3, 40, camera, hand[0])
    tail = int(round(NO_HAND_TAIL_FRACTION * 40))
    uv = camera.project(hand[0].keypoints(poses[-1]))
    assert not ((uv[:, 0] >= 0) & (uv[:, 0] < 640)).any() and tail > 0
    factors = varied_finger_factors(3)
    assert len(factors) == 5 and all(0.9 <= f <= 1.1 for f in factors)
    assert factors != varied_finger_factors(4)


def test_a_glove_on_the_image_border_is_not_fully_visible() -> None:
    labels = np.zeros((48, 64), np.uint8)
    labels[10:30, 20:40] = 3
    keypoints = np.array([[25.0, 15.0], [35.0, 25.0]])
    assert fully_visible(labels, keypoints)
    assert not fully_visible(labels, keypoints + [40.0, 0.0])       # a keypoint outside
    assert not fully_visible(np.zeros_like(labels), keypoints)       # no glove
    for edge in ((0, slice(20, 40)), (-1, slice(20, 40)), (slice(5, 9), 0),
                 (slice(5, 9), -1)):
        cut = labels.copy()
        cut[edge] = 5                                                # fingers run off it
        assert not fully_visible(cut, keypoints)


def test_eval_scenes_prints_and_writes_the_ladder(node_assets, tmp_path, capsys) -> None:
    out = tmp_path / 'ladder.json'
    code = eval_scenes.main(['--conditions', 'clean', 'borders', '--sequences', '1',
                             '--frames', '24', '--database', str(node_assets.database),
                             '--color-config', str(node_assets.color_config),
                             '--max-weak-match-residual-px', '7.5', '--json', str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert 'Real-scene ladder' in text and 'Targets' in text
    figures = json.loads(out.read_text())
    rows = {r['condition']: r for r in figures['rows']}
    assert set(rows) == {'clean', 'borders'}
    assert figures['settings']['max_weak_match_residual_px'] == 7.5
    for row in rows.values():
        assert row['frames'] == 24 and row['no_hand_frames'] >= 4
        assert row['no_hand_with_pose_count'] == 0
        assert row['partial_depth_over_100mm'] == 0
    assert any(t['target'].startswith('clean: fully visible') for t in figures['targets'])
    # the segmentation time target is read with the machine's speed before and after
    assert [row['when'] for row in figures['settings']['machine_speed']] == ['before', 'after']
    assert MACHINE_SPEED_TITLE in text


def test_eval_scenes_refuses_a_missing_database(tmp_path, capsys) -> None:
    assert eval_scenes.main(['--database', str(tmp_path / 'none'), '--sequences', '1']) != 0


def test_eval_scenes_writes_every_frame_with_its_evidence(node_assets, tmp_path) -> None:
    out, frames_out = tmp_path / 'ladder.json', tmp_path / 'frames.json'
    code = eval_scenes.main(['--conditions', 'clean', 'proportions', '--sequences', '1',
                             '--frames', '24', '--database', str(node_assets.database),
                             '--color-config', str(node_assets.color_config),
                             '--json', str(out), '--frames-json', str(frames_out)])
    assert code == 0
    rows = {r['condition']: r for r in json.loads(out.read_text())['rows']}
    frames = json.loads(frames_out.read_text())['frames']
    for name, row in rows.items():
        mine = [f for f in frames if f['condition'] == name]
        assert [f['frame'] for f in mine] == list(range(24))
        assert sum(f['class'] == 'no hand' for f in mine) == row['no_hand_frames']
        assert sum(f['class'] == 'fully visible' for f in mine) == row['fully_visible_frames']
        posed = [f for f in mine if f['tracked'] and f['class'] != 'no hand']
        assert len(posed) == row['tracked_frames'] > 0
        off = sum(f['fingertip_mean_mm'] > 50.0 for f in posed)
        assert off == round(row['off_50mm'] * row['tracked_frames'])
        for f in posed:
            assert f['reason'] == '' and len(f['fingertip_mm']) == 5
            assert np.isclose(np.mean(f['fingertip_mm']), f['fingertip_mean_mm'])
            assert f['constraints'] > 0 and f['residual_px'] > 0.0
            assert 0.0 <= f['explained_blob_share'] <= 1.0 and f['image_distance'] >= 0.0
        lost = [f for f in mine if not f['tracked'] and f['class'] != 'no hand']
        assert all(f['reason'] for f in lost)
        assert sum(f['class'] == 'fully visible' and f['tracked'] for f in mine) == round(
            row['visible_tracked'] * row['fully_visible_frames'])


def test_eval_scenes_records_each_stage_error_against_the_truth(node_assets, tmp_path) -> None:
    frames_out = tmp_path / 'frames.json'
    code = eval_scenes.main(['--conditions', 'clean', '--sequences', '1', '--frames', '24',
                             '--database', str(node_assets.database),
                             '--color-config', str(node_assets.color_config),
                             '--frames-json', str(frames_out)])
    assert code == 0
    frames = json.loads(frames_out.read_text())['frames']
    stages = ('nearest', 'blend', 'prior', 'previous')
    tracked_before = False
    carried = 0
    for f in frames:
        if f['class'] == 'no hand':
            assert not any(f'{s}_mm' in f for s in stages)
        elif f['tracked']:
            for s in ('nearest', 'blend', 'prior'):
                assert f[f'{s}_mm'] >= 0.0 and np.isfinite(f[f'{s}_depth_mm'])
            # the previous output is this frame's stage exactly when the frame before was
            # tracked (a refusal or a lost frame resets the tracker)
            assert ('previous_mm' in f) == tracked_before
            carried += 'previous_mm' in f
        tracked_before = f['tracked']
    assert carried > 0
