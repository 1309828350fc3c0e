"""Pair the tracker's ``JointState`` and wrist ``PoseStamped`` of one frame (same header stamp)
into the 26-DOF pose, for the nodes that consume the tracked hand. No rclpy import."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState

from colorglove_ros.core.hand.model import FINGER_DOF_NAMES
from colorglove_ros.ros.conversions import pose_from_msgs, stamp_key

__all__ = ['PosePairer', 'is_no_hand_status']


def is_no_hand_status(text: str) -> bool:
    """Whether an ``ik_node`` tracking-status line reports the hand lost."""
    return text.startswith('no hand')


class PosePairer:
    """Keeps the newest JointState and wrist pose; :meth:`add_joints` / :meth:`add_wrist`
    return ``(pose, wrist message)`` once both halves of one frame are in, else None. The
    finger joints are read by ``joint_names`` (``FINGER_DOF_NAMES`` order; default the plain
    names, a prefixed hand's from ``core.hand.frames.finger_joint_names``)."""

    def __init__(self, joint_names: Sequence[str] = FINGER_DOF_NAMES) -> None:
        self.joint_names = tuple(joint_names)
        self._joints: JointState | None = None
        self._wrist: PoseStamped | None = None

    @staticmethod
    def _key(msg) -> tuple[int, int]:
        return stamp_key(msg.header.stamp)

    def _pair(self) -> tuple[np.ndarray, PoseStamped] | None:
        if self._joints is None or self._wrist is None or \
                self._key(self._joints) != self._key(self._wrist):
            return None
        joints, wrist = self._joints, self._wrist
        self._joints = self._wrist = None
        return pose_from_msgs(joints, wrist, self.joint_names), wrist

    def add_joints(self, msg: JointState) -> tuple[np.ndarray, PoseStamped] | None:
        """Keep a JointState; the frame's pose if its wrist pose has arrived."""
        self._joints = msg
        return self._pair()

    def add_wrist(self, msg: PoseStamped) -> tuple[np.ndarray, PoseStamped] | None:
        """Keep a wrist pose; the frame's pose if its JointState has arrived."""
        self._wrist = msg
        return self._pair()
