"""Hand poses for tests: the default hand model and finger shapes made into poses it allows."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.poses import finger_limits, full_pose

__all__ = ['MODEL', 'allowed_fingers', 'hand_pose']

MODEL = HandModel()


def allowed_fingers(fingers: np.ndarray) -> np.ndarray:
    """The finger DOFs (20,) clipped to the limits of :data:`MODEL`."""
    lo, hi = finger_limits(MODEL)
    return np.clip(fingers, lo, hi)


def hand_pose(fingers: np.ndarray, global_pose: np.ndarray | None = None) -> np.ndarray:
    """A 26-DOF pose of :data:`MODEL`: ``fingers`` clipped to its limits, ``global_pose``
    (6,) or the rest pose's."""
    return full_pose(MODEL, allowed_fingers(fingers), global_pose)
