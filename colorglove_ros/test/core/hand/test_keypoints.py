"""The 21 keypoints: MediaPipe order, the wrist and camera frames, and the worked example of
docs/DESIGN.md ("Keypoints")."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.hand.keypoints import (
    FINGERTIP_INDICES,
    MEDIAPIPE_NAMES,
    camera_to_wrist,
    hand_keypoints,
    wrist_to_camera,
)
from colorglove_ros.core.hand.model import KEYPOINT_NAMES, HandModel, HandModelError

_DIGIT_WORDS = {'thumb': 'THUMB', 'index': 'INDEX_FINGER', 'middle': 'MIDDLE_FINGER',
                'ring': 'RING_FINGER', 'little': 'PINKY'}


def test_order_is_mediapipe() -> None:
    assert MEDIAPIPE_NAMES[0] == 'WRIST' and KEYPOINT_NAMES[0] == 'wrist'
    for ours, theirs in zip(KEYPOINT_NAMES[1:], MEDIAPIPE_NAMES[1:], strict=True):
        digit, joint = ours.split('_')
        assert theirs == f'{_DIGIT_WORDS[digit]}_{joint.upper()}'
    assert [MEDIAPIPE_NAMES[i] for i in FINGERTIP_INDICES] == [
        'THUMB_TIP', 'INDEX_FINGER_TIP', 'MIDDLE_FINGER_TIP', 'RING_FINGER_TIP', 'PINKY_TIP']


@pytest.mark.parametrize('seed', range(4))
def test_frames_agree(seed: int) -> None:
    model = HandModel()
    rng = np.random.default_rng(seed)
    q = model.rest_pose()
    q[0:3] = rng.uniform([-0.2, -0.2, 0.3], [0.2, 0.2, 0.8])
    q[3:6] = rng.normal(0.0, 1.0, 3)
    q[6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:])
    camera = hand_keypoints(model, q, 'camera')
    wrist = hand_keypoints(model, q, 'wrist')
    np.testing.assert_allclose(camera.positions, model.keypoints(q), atol=1e-12)
    np.testing.assert_allclose(wrist.positions[0], 0.0, atol=1e-12)
    R, t = wrist_to_camera(q)
    np.testing.assert_allclose(wrist.positions @ R.T + t, camera.positions, atol=1e-12)
    np.testing.assert_allclose(camera_to_wrist(q, camera.positions), wrist.positions, atol=1e-12)
    np.testing.assert_allclose(np.einsum('ij,njk->nik', R, wrist.rotations), camera.rotations,
                               atol=1e-12)
    # the wrist-frame keypoints do not depend on the global pose
    q2 = q.copy()
    q2[0:6] = [0.1, 0.0, 0.4, 0.3, -0.2, 1.0]
    np.testing.assert_allclose(hand_keypoints(model, q2, 'wrist').positions, wrist.positions,
                               atol=1e-12)
    assert np.allclose(np.linalg.det(camera.rotations), 1.0)


def test_worked_example_of_the_design_doc() -> None:
    """docs/DESIGN.md: flat 0.19 m hand, wrist at (0.05, 0.02, 0.5), turned 90 deg about the
    camera z axis: the fingers point to the image right."""
    model = HandModel(0.19)
    q = np.zeros(26)
    q[0:3] = [0.05, 0.02, 0.5]
    q[5] = np.pi / 2
    wrist = hand_keypoints(model, q, 'wrist').positions
    camera = hand_keypoints(model, q, 'camera').positions
    np.testing.assert_allclose(wrist[8], [0.0363, -0.1770, 0.0], atol=5e-5)
    np.testing.assert_allclose(camera[8], [0.2270, 0.0563, 0.5], atol=5e-5)
    np.testing.assert_allclose(wrist[12], [0.0060, -0.1899, 0.0], atol=5e-5)
    np.testing.assert_allclose(camera[12], [0.2399, 0.0260, 0.5], atol=5e-5)
    assert wrist[4][0] > 0 > wrist[20][0]          # thumb on +x, little finger on -x


def test_bad_input() -> None:
    model = HandModel()
    with pytest.raises(HandModelError):
        hand_keypoints(model, np.zeros(25))
    with pytest.raises(HandModelError):
        hand_keypoints(model, model.rest_pose(), 'world')
    q = model.rest_pose()
    q[7] = np.nan
    with pytest.raises(HandModelError):
        hand_keypoints(model, q)
