"""Tests for the hand's frame and joint naming (``core/hand/frames.py``) and its use by the URDF
generator."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from colorglove_ros.core.hand.frames import (
    FramePrefixError,
    check_frame_prefix,
    finger_joint_names,
    hand_root_frame,
    prefixed_joint_names,
    prefixed_name,
)
from colorglove_ros.core.hand.model import FINGER_DOF_NAMES, LINK_NAMES
from colorglove_ros.core.hand.urdf import tip_link_name, urdf_string


def test_default_prefix_keeps_the_plain_names() -> None:
    assert hand_root_frame() == 'palm' == LINK_NAMES[0]
    assert prefixed_name('index_proximal') == 'index_proximal'
    assert finger_joint_names() == list(FINGER_DOF_NAMES)


def test_prefix_goes_in_front_of_every_name() -> None:
    assert hand_root_frame('right_') == 'right_palm'
    assert prefixed_name('index_pip_flex', 'hand1/') == 'hand1/index_pip_flex'
    names = finger_joint_names('right_')
    assert len(names) == 20 and names[0] == 'right_thumb_cmc_abd'
    assert names == prefixed_joint_names(FINGER_DOF_NAMES, 'right_')
    assert all(n == f'right_{plain}' for n, plain in zip(names, FINGER_DOF_NAMES, strict=True))


@pytest.mark.parametrize('prefix', ['right_', 'left_', 'h', 'hand1/', 'robot/left_', 'A9_b'])
def test_valid_prefixes(prefix: str) -> None:
    assert check_frame_prefix(prefix) == prefix


@pytest.mark.parametrize('prefix', ['/right_', '1hand_', '_right', 'right hand', 'a//b',
                                    'right-', 'r\u00e9_', 'x\n', 5, None])
def test_invalid_prefixes_are_refused(prefix) -> None:
    with pytest.raises(FramePrefixError, match='frame prefix'):
        check_frame_prefix(prefix)
    with pytest.raises(FramePrefixError):
        prefixed_name('palm', prefix)


def _names(root: ET.Element) -> tuple[list[str], list[str], list[str]]:
    """Link names, joint names, and every link a joint refers to (parent and child)."""
    links = [link.get('name') for link in root.iter('link')]
    joints = [joint.get('name') for joint in root.iter('joint')]
    referred = [e.get('link') for joint in root.iter('joint') for e in joint
                if e.tag in ('parent', 'child')]
    return links, joints, referred


@pytest.mark.parametrize('prefix', ['right_', 'hand2/'])
def test_urdf_names_carry_the_prefix(prefix: str) -> None:
    plain_links, plain_joints, plain_referred = _names(ET.fromstring(urdf_string()))
    links, joints, referred = _names(ET.fromstring(urdf_string(frame_prefix=prefix)))
    assert links == prefixed_joint_names(plain_links, prefix)
    assert joints == prefixed_joint_names(plain_joints, prefix)
    assert referred == prefixed_joint_names(plain_referred, prefix)
    assert links[0] == hand_root_frame(prefix)
    assert set(finger_joint_names(prefix)) <= set(joints)
    assert prefixed_name(tip_link_name('index'), prefix) in links
    # only the root link is no joint's child
    children = {e.get('link') for e in ET.fromstring(urdf_string(frame_prefix=prefix))
                .iter('child')}
    assert set(links) - children == {hand_root_frame(prefix)}


def test_urdf_refuses_a_bad_prefix() -> None:
    with pytest.raises(FramePrefixError):
        urdf_string(frame_prefix='bad prefix')
