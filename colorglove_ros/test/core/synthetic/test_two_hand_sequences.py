"""Two-hand sequences (core.synthetic.sequences.two_hand_sequences): the left hand is the mirror
of its own sequence, and 'apart' keeps each hand on its side of the image."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.handedness import hand_keypoints, mirror_pose
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.core.synthetic.sequences import (
    LEFT_SEED_OFFSET,
    generate_sequence,
    two_hand_sequences,
)

MODEL = default_hand()[0]
CAMERA = default_camera()


def _centre_columns(poses: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {h: CAMERA.project(hand_keypoints(MODEL, q, h).reshape(-1, 3)).reshape(
        len(q), -1, 2)[:, :, 0].mean(axis=1) for h, q in poses.items()}


def test_free_paths_are_the_sequence_and_the_mirrored_one():
    poses = two_hand_sequences(4, 20, camera=CAMERA, model=MODEL, apart=False)
    np.testing.assert_allclose(poses['right'], generate_sequence(4, 20, camera=CAMERA,
                                                                 model=MODEL))
    left = generate_sequence(4 + LEFT_SEED_OFFSET, 20, camera=CAMERA, model=MODEL)
    np.testing.assert_allclose(poses['left'], np.stack([mirror_pose(q) for q in left]))


@pytest.mark.parametrize('seed', [0, 1000])
def test_apart_keeps_each_hand_on_its_side(seed):
    free = two_hand_sequences(seed, 90, camera=CAMERA, model=MODEL, apart=False)
    apart = two_hand_sequences(seed, 90, camera=CAMERA, model=MODEL)
    for h in free:       # only the wrist moves, parallel to the image plane
        np.testing.assert_allclose(apart[h][:, 2:], free[h][:, 2:])
    u = _centre_columns(apart)
    assert np.mean(u['right'] < u['left']) > 0.95   # a user facing the camera: right on the left
    assert np.all(u['right'] < CAMERA.cx) and np.all(u['left'] > CAMERA.cx)
    spread = {h: np.ptp(c) for h, c in _centre_columns(free).items()}
    for h in apart:      # squeezed toward its side
        assert np.ptp(u[h]) < 0.6 * spread[h]
