"""The left glove end to end: the synthesiser's left hand is the mirror image of the right one,
the mirrored query of a rendered left hand is the right hand's query, the evaluator tracks a
left hand through the right-hand lookup and tracker and mirrors the pose back, and
colorglove_eval_left_glove compares the two gloves."""
from __future__ import annotations

import json

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.evaluation.sequences import (
    EvaluationError,
    SequenceEvaluator,
    summarize,
    truth_observer,
)
from colorglove_ros.core.hand.handedness import (
    HandednessError,
    hand_keypoints,
    mirror_pose,
    mirrored_observer,
)
from colorglove_ros.core.lookup.database import load_database
from colorglove_ros.core.lookup.search import PoseLookup
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.core.synthetic.frames import Synthesizer, default_camera, sample_pose
from colorglove_ros.tools import eval_left_glove

CAMERA = default_camera()      # principal point at the image centre: mirroring flips columns


@pytest.fixture(scope='module')
def synths():
    out = {hand: Synthesizer(handedness=hand) for hand in ('right', 'left')}
    yield out
    for s in out.values():
        s.release()


def _pair(synths, seed: int):
    q = sample_pose(np.random.default_rng(seed), CAMERA, out_of_frame_prob=0.0)
    cond = sample_conditions(np.random.default_rng(seed), 'test')
    right = synths['right'].render_frame(q, CAMERA, np.random.default_rng(1), cond)
    left = synths['left'].render_frame(mirror_pose(q), CAMERA, np.random.default_rng(1), cond)
    return q, right, left


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_rendered_left_hand_is_the_mirror_image_of_the_right(synths, seed):
    q, right, left = _pair(synths, seed)
    assert (right.labels > 0).sum() > 500
    # equal but for a rare pixel whose centre lies on a triangle edge (rasteriser ties)
    assert np.count_nonzero(left.labels != right.labels[:, ::-1]) <= 2
    assert np.count_nonzero(left.patch_ids != right.patch_ids[:, ::-1]) <= 2
    assert np.allclose(left.keypoints_3d, right.keypoints_3d * [-1.0, 1.0, 1.0])
    assert np.allclose(left.keypoints_3d, hand_keypoints(synths['left'].model, left.pose, 'left'))
    # a left hand is not a right hand at the same pose: the picture differs
    assert not np.array_equal(left.labels, right.labels)


def test_mirrored_query_of_the_left_hand_is_the_right_hands_query(synths):
    _q, right, left = _pair(synths, 3)
    observe = truth_observer()
    seen_r, tiny_r = observe(right, True)
    seen_l, tiny_l = mirrored_observer(observe, CAMERA.cx)(left, True)
    assert np.array_equal(tiny_l.labels, tiny_r.labels)
    assert np.allclose([tiny_l.transform.scale, tiny_l.transform.offset_x,
                        tiny_l.transform.offset_y],
                       [tiny_r.transform.scale, tiny_r.transform.offset_x,
                        tiny_r.transform.offset_y])
    order_r = np.lexsort((seen_r.blobs.centroid_px[:, 1], seen_r.blobs.color))
    order_l = np.lexsort((seen_l.blobs.centroid_px[:, 1], seen_l.blobs.color))
    assert np.array_equal(seen_l.blobs.color[order_l], seen_r.blobs.color[order_r])
    assert np.allclose(seen_l.blobs.centroid_px[order_l], seen_r.blobs.centroid_px[order_r])
    with pytest.raises(HandednessError):
        mirrored_observer(observe, CAMERA.cx)(left, False)


def test_render_hands_puts_both_hands_in_one_frame(synths):
    q = sample_pose(np.random.default_rng(4), CAMERA, out_of_frame_prob=0.0)
    q_right, q_left = q.copy(), mirror_pose(q)
    q_right[0] += 0.12                       # apart, so neither hides the other
    q_left[0] -= 0.12
    cond = sample_conditions(np.random.default_rng(4), 'test')
    frame, which = synths['right'].render_hands([(q_right, 'right'), (q_left, 'left')],
                                                CAMERA, np.random.default_rng(1), cond)
    alone = synths['left'].render_frame(q_left, CAMERA, np.random.default_rng(1), cond)
    assert set(np.unique(which)) == {0, 1, 2}
    assert np.array_equal(which == 2, alone.labels > 0)
    assert np.array_equal(frame.labels[which == 2], alone.labels[which == 2])
    assert frame.patch_ids.max() <= 20
    assert np.allclose(frame.pose, q_right)


def test_left_hand_is_tracked_as_the_mirrored_right_hand(small_database_path):
    mono = load_calibration(CONFIG_DIR / 'calibration.yaml')
    lookup = PoseLookup(load_database(small_database_path))
    runs = {}
    for hand in ('right', 'left'):
        ev = SequenceEvaluator(lookup, {'1': mono.cameras}, ('ik_smooth',), hand=hand)
        runs[hand] = ev.run(0, 6)[('1', 'ik_smooth')]
        model = ev.model
        ev.close()
    right, left = runs['right'], runs['left']
    assert left.hand == 'left' and right.found.sum() >= 4
    assert np.allclose(left.q_true, mirror_pose(right.q_true))
    assert np.array_equal(left.found, right.found)
    # the mirrored query is the right hand's query (truth labels, equal but for rasteriser
    # ties): the same fit, mirrored back
    est_l = hand_keypoints(model, left.q_est[left.found], 'left')
    est_r = hand_keypoints(model, right.q_est[right.found], 'right')
    assert np.abs(est_l - est_r * [-1.0, 1.0, 1.0]).max() < 1e-3
    s_left, s_right = summarize(model, [left]), summarize(model, [right])
    assert s_left['fingertip_mm'] == pytest.approx(s_right['fingertip_mm'], abs=0.1)


def test_left_hand_evaluation_needs_one_camera_and_a_left_synthesiser(small_database_path,
                                                                       synths):
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml')
    lookup = PoseLookup(load_database(small_database_path))
    with pytest.raises(EvaluationError, match='one camera'):
        SequenceEvaluator(lookup, {'2': stereo.cameras}, hand='left', synthesizer=synths['left'])
    with pytest.raises(EvaluationError, match='renders a right hand'):
        SequenceEvaluator(lookup, {'1': stereo.cameras[:1]}, hand='left',
                          synthesizer=synths['right'])


def test_eval_left_glove_cli_prints_and_writes_json(small_database_path, tmp_path, capsys):
    out = tmp_path / 'left.json'
    assert eval_left_glove.main(['--database', str(small_database_path), '--sequences', '1',
                                 '--frames', '4', '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'left - right' in text and 'PASS' in text
    data = json.loads(out.read_text())
    assert [r['glove'] for r in data['rows']] == ['right', 'left', 'left - right']
    assert len(data['targets']) == 2
    # truth labels: the mirrored query is exact, so the two gloves measure the same
    assert abs(data['rows'][2]['fingertip_mm']) < 0.1


def test_exported_left_glove_is_the_mirror_image(tmp_path, synths):
    import trimesh

    from colorglove_ros.core.hand.glove import export_glove_mesh

    s = synths['right']
    paths = {hand: export_glove_mesh(s.mesh, s.glove, s.model, tmp_path / f'{hand}.ply',
                                     hand=hand) for hand in ('right', 'left')}
    right, left = (trimesh.load(paths[h], process=False) for h in ('right', 'left'))
    assert np.allclose(left.vertices, right.vertices * [-1.0, 1.0, 1.0], atol=1e-6)
    assert np.array_equal(left.faces, right.faces[:, ::-1])
    assert np.array_equal(left.visual.face_colors, right.visual.face_colors)
    assert np.allclose(left.face_normals, right.face_normals * [-1.0, 1.0, 1.0], atol=1e-6)
