"""Hand poses for tests: the default hand model and finger shapes made into poses it allows."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.poses import finger_limits, full_pose

__all__ = ['MODEL', 'allowed_fingers', 'hand_pose', 'random_poses']

MODEL = HandModel()


def allowed_fingers(fingers: np.ndarray) -> np.ndarray:
    """The finger DOFs (20,) clipped to the limits of :data:`MODEL`."""
    lo, hi = finger_limits(MODEL)
    return np.clip(fingers, lo, hi)


def hand_pose(fingers: np.ndarray, global_pose: np.ndarray | None = None) -> np.ndarray:
    """A 26-DOF pose of :data:`MODEL`: ``fingers`` clipped to its limits, ``global_pose``
    (6,) or the rest pose's."""
    return full_pose(MODEL, allowed_fingers(fingers), global_pose)


def random_poses(model: HandModel, count: int, seed: int, rotation_sd: float) -> list[np.ndarray]:
    """``count`` poses of ``model`` in front of a camera: the wrist 0.35-0.8 m away near the
    optical axis, its rotation vector normal with ``rotation_sd`` (rad) per axis, the fingers
    uniform within their limits (clamped)."""
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(count):
        q = model.rest_pose()
        q[:3] = [rng.normal(0.0, 0.05), rng.normal(0.0, 0.05), rng.uniform(0.35, 0.8)]
        q[3:6] = rng.normal(0.0, rotation_sd, 3)
        q[6:] = rng.uniform(model.lower_limits[6:], model.upper_limits[6:])
        poses.append(model.clamp(q))
    return poses
