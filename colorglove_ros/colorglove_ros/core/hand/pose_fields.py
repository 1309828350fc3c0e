"""The 26-DOF pose vector as the fields of ROS messages (wrist position, quaternion, finger
joints) and back, in plain numpy (``core.geometry``): shared by the rclpy and the rosbags message
builders, and light to import."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.geometry import quaternion_to_rotvec, rotvec_to_quaternion
from colorglove_ros.core.hand.model import NUM_DOFS

__all__ = ['pose_from_fields', 'wrist_quaternion']


def pose_from_fields(position: np.ndarray, quaternion_xyzw: np.ndarray,
                     finger_joints: np.ndarray) -> np.ndarray:
    """q (26,) from the wrist position (metres), orientation quaternion (x, y, z, w) and the
    20 finger joint angles in ``FINGER_DOF_NAMES`` order."""
    q = np.empty(NUM_DOFS)
    q[0:3] = position
    q[3:6] = quaternion_to_rotvec(np.asarray(quaternion_xyzw, dtype=float))
    q[6:] = finger_joints
    return q


def wrist_quaternion(q: np.ndarray) -> np.ndarray:
    """The wrist orientation of pose ``q`` as a unit quaternion (x, y, z, w)."""
    return rotvec_to_quaternion(np.asarray(q, dtype=float)[3:6])
