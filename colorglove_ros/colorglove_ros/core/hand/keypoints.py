"""The 21 hand keypoints in MediaPipe / MANO order, in the camera frame and in the wrist frame.

Order (``MEDIAPIPE_NAMES``, index: name): 0 wrist; thumb 1 CMC, 2 MCP, 3 IP, 4 tip; index
5 MCP, 6 PIP, 7 DIP, 8 tip; middle 9-12; ring 13-16; little (pinky) 17-20. It is MediaPipe
Hands' landmark order, which OpenPose's hand model and the retargeting libraries that take
21 MANO keypoints (dex-retargeting and others) use as well. It equals
``HandModel.keypoint_names``, so the keypoints come straight from the model's forward
kinematics (``HandModel.keypoints``).

Frames (metres, right-handed):

* **camera**: the OpenCV optical frame of the camera (x right, y down, z forward), the frame
  of ``/hand/wrist_pose``;
* **wrist**: the hand root frame (URDF link ``palm``, origin at the wrist joint centre), for
  a right hand ``+x`` toward the thumb side, ``+y`` toward the forearm (fingers point along
  ``-y``), ``+z`` out of the back of the hand. ``p_camera = R @ p_wrist + t`` with
  ``t = q[0:3]`` and ``R = rotvec_to_matrix(q[3:6])``; keypoint 0 (the wrist) is the origin.

Each keypoint also carries an orientation: that of the link whose proximal joint it is (the
palm for the wrist, the distal phalanx for a fingertip), so a phalanx points along its
frame's ``-y`` and flexes about its ``+x``. See docs/DESIGN.md, "Keypoints", for a worked
example.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colorglove_ros.core.geometry import rotvec_to_matrix
from colorglove_ros.core.hand.model import KEYPOINT_NAMES, NUM_DOFS, HandModel, HandModelError

__all__ = [
    'MEDIAPIPE_NAMES', 'NUM_KEYPOINTS', 'FINGERTIP_INDICES', 'KEYPOINT_FRAMES', 'HandKeypoints',
    'keypoint_link_indices', 'hand_keypoints', 'camera_to_wrist', 'wrist_to_camera',
]

MEDIAPIPE_NAMES: tuple[str, ...] = (
    'WRIST', 'THUMB_CMC', 'THUMB_MCP', 'THUMB_IP', 'THUMB_TIP',
    'INDEX_FINGER_MCP', 'INDEX_FINGER_PIP', 'INDEX_FINGER_DIP', 'INDEX_FINGER_TIP',
    'MIDDLE_FINGER_MCP', 'MIDDLE_FINGER_PIP', 'MIDDLE_FINGER_DIP', 'MIDDLE_FINGER_TIP',
    'RING_FINGER_MCP', 'RING_FINGER_PIP', 'RING_FINGER_DIP', 'RING_FINGER_TIP',
    'PINKY_MCP', 'PINKY_PIP', 'PINKY_DIP', 'PINKY_TIP')
NUM_KEYPOINTS = 21
# thumb, index, middle, ring, little fingertips
FINGERTIP_INDICES: tuple[int, ...] = (4, 8, 12, 16, 20)
KEYPOINT_FRAMES: tuple[str, ...] = ('camera', 'wrist')

assert len(MEDIAPIPE_NAMES) == len(KEYPOINT_NAMES) == NUM_KEYPOINTS
assert all(KEYPOINT_NAMES[i].endswith('_tip') for i in FINGERTIP_INDICES)


@dataclass(frozen=True)
class HandKeypoints:
    """21 keypoints in one frame: ``positions`` (21, 3) metres and ``rotations`` (21, 3, 3),
    each the orientation of the keypoint's link in ``frame`` ('camera' or 'wrist')."""

    positions: np.ndarray
    rotations: np.ndarray
    frame: str


def keypoint_link_indices(model: HandModel) -> np.ndarray:
    """(21,) index in ``LINK_NAMES`` of the link each keypoint sits on (its orientation)."""
    return np.asarray(model.keypoint_link, dtype=np.int64)


def _check_pose(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (NUM_DOFS,) or not np.all(np.isfinite(q)):
        raise HandModelError(f'pose must be 26 finite values, got shape {q.shape}')
    return q


def wrist_to_camera(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (3, 3) and translation (3,) of the wrist frame in the camera frame:
    ``p_camera = R @ p_wrist + t``."""
    q = _check_pose(q)
    return rotvec_to_matrix(q[3:6]), q[0:3].copy()


def camera_to_wrist(q: np.ndarray, points_camera: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) -> the same points in the wrist frame of pose ``q``."""
    R, t = wrist_to_camera(q)
    return (np.asarray(points_camera, dtype=float) - t) @ R


def hand_keypoints(model: HandModel, q: np.ndarray, frame: str = 'camera') -> HandKeypoints:
    """The 21 keypoints of pose ``q`` (26,) in ``frame`` ('camera' or 'wrist'), by the model's
    forward kinematics."""
    if frame not in KEYPOINT_FRAMES:
        raise HandModelError(f'frame must be one of {KEYPOINT_FRAMES}, got {frame!r}')
    q = _check_pose(q)
    transforms = model.link_transforms(q)[keypoint_link_indices(model)]
    rotations = transforms[:, :3, :3]
    positions = model.keypoints(q)
    if frame == 'wrist':
        R, _ = wrist_to_camera(q)
        positions = camera_to_wrist(q, positions)
        rotations = np.einsum('ji,njk->nik', R, rotations)
    return HandKeypoints(positions=positions, rotations=rotations, frame=frame)
