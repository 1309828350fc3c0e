"""URDF of a right or left hand with a name prefix (``left_``, ``right_``) on every link and
joint, built by ``core/hand/urdf.py``'s generator (names from ``core/hand/frames.py``).

The left hand is the right model mirrored in its hand frame by ``S = diag(-1, 1, 1)``
(``core/hand/handedness.py``): every joint origin ``(R, t) -> (S R S, S t)`` and axis
``a -> -S a`` (an axis is a pseudovector), so the joint angles keep their meaning and a left
hand's JointState reads like a right hand's. The root link is ``<prefix>palm``; the camera ->
``<prefix>palm`` transform is the hand's wrist pose.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from colorglove_ros.core.hand.frames import prefixed_joint_names
from colorglove_ros.core.hand.handedness import HandednessError, check_hand
from colorglove_ros.core.hand.model import HandModel, JointSpec
from colorglove_ros.core.hand.urdf import URDF_NAME, UrdfError, urdf_string

__all__ = ['hand_urdf_string', 'mirrored_joints', 'prefixed_joint_names']

_S = np.diag([-1.0, 1.0, 1.0])


def mirrored_joints(model: HandModel) -> tuple[JointSpec, ...]:
    """The model's joints mirrored into the left hand."""
    return tuple(replace(j, fixed_rot=_S @ j.fixed_rot @ _S, fixed_trans=_S @ j.fixed_trans,
                         axis=-(_S @ j.axis)) for j in model.joints)


@dataclass(frozen=True)
class _MirroredModel:
    """What ``urdf_string`` reads from a model, with the joints mirrored."""

    base: HandModel

    def __getattr__(self, name: str):
        return getattr(self.base, name)

    @property
    def joints(self) -> tuple[JointSpec, ...]:
        return mirrored_joints(self.base)


def hand_urdf_string(hand: str = 'right', prefix: str | None = None,
                     model: HandModel | None = None) -> str:
    """URDF of a ``hand`` ('right' or 'left') whose link and joint names start with ``prefix``
    (default ``'<hand>_'``; '' keeps the plain names)."""
    try:
        check_hand(hand)
    except HandednessError as exc:
        raise UrdfError(str(exc)) from exc
    prefix = f'{hand}_' if prefix is None else prefix
    model = HandModel() if model is None else model
    source = model if hand == 'right' else _MirroredModel(model)
    return urdf_string(source, name=f'{URDF_NAME}_{hand}',  # type: ignore[arg-type]
                       frame_prefix=prefix)
