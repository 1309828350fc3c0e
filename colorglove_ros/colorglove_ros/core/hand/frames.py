"""Names of the frames and joints the package publishes for one hand, with the hand's prefix.

A ``frame_prefix`` (the hand's name, e.g. ``'right_'``) goes in front of every link (TF frame)
and joint name: ``'right_palm'``, ``'right_index_pip_flex'``. The default ``''`` keeps the
plain names (``'palm'``). The URDF generator (``core/hand/urdf.py``), the TF child frame and
the ``JointState`` names of the nodes all take their names from :func:`prefixed_name`, so a
robot_state_publisher fed the URDF finds the joints the tracker publishes, and two hands (or a
robot hand's URDF) do not clash.
"""
from __future__ import annotations

import re
from collections.abc import Iterable

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import FINGER_DOF_NAMES, LINK_NAMES

__all__ = ['DEFAULT_FRAME_PREFIX', 'HAND_ROOT_LINK', 'FramePrefixError', 'check_frame_prefix',
           'prefixed_name', 'hand_root_frame', 'prefixed_joint_names', 'finger_joint_names']

DEFAULT_FRAME_PREFIX = ''
"""No prefix: the plain link and joint names."""
HAND_ROOT_LINK = LINK_NAMES[0]
"""The URDF's root link (``palm``): the child frame of the camera -> hand transform."""

# a TF frame id must not start with '/'; letters first, then letters, digits, '_' and single '/'
_PREFIX_PATTERN = re.compile(r'[A-Za-z][A-Za-z0-9_]*(/[A-Za-z0-9_]+)*/?')


class FramePrefixError(ColorGloveError, ValueError):
    """A frame prefix that would not make valid frame and joint names."""


def check_frame_prefix(prefix: str) -> str:
    """Return ``prefix`` if it makes valid names: empty, or a letter followed by letters,
    digits, ``_`` and single ``/`` (e.g. ``right_``, ``hand1/``); else raise
    :class:`FramePrefixError` naming it."""
    if not isinstance(prefix, str):
        raise FramePrefixError(f'frame prefix must be a string, got {prefix!r}')
    if prefix and not _PREFIX_PATTERN.fullmatch(prefix):
        raise FramePrefixError(
            f'frame prefix {prefix!r} is not valid: use letters, digits, "_" and single "/", '
            'starting with a letter (e.g. "right_"), or "" for the plain names')
    return prefix


def prefixed_name(name: str, prefix: str = DEFAULT_FRAME_PREFIX) -> str:
    """The published name of link, frame or joint ``name`` for the hand ``prefix``."""
    return f'{check_frame_prefix(prefix)}{name}'


def hand_root_frame(prefix: str = DEFAULT_FRAME_PREFIX) -> str:
    """The hand's root frame (``<prefix>palm``): the child of the camera -> hand transform."""
    return prefixed_name(HAND_ROOT_LINK, prefix)


def prefixed_joint_names(names: Iterable[str], prefix: str) -> list[str]:
    """``names`` with the hand ``prefix`` (the names a prefixed JointState carries)."""
    return [prefixed_name(name, prefix) for name in names]


def finger_joint_names(prefix: str = DEFAULT_FRAME_PREFIX) -> list[str]:
    """The 20 finger joints' names for the hand ``prefix``, in ``FINGER_DOF_NAMES`` order."""
    return prefixed_joint_names(FINGER_DOF_NAMES, prefix)
