"""The URDF of the user's hand (``core.hand.urdf.calibrated_hand_urdf``): sized by the
calibration file's hand length and finger length factors, read back with xml.etree."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from calibration_files import calibration_with_hand_length
from hand_calibration_files import UNEVEN_FACTORS, calibration_with_hand
from repo_paths import CONFIG_DIR
from scipy.spatial.transform import Rotation

from colorglove_ros.core.camera import CalibrationError
from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.hand.frames import HAND_ROOT_LINK, hand_root_frame, prefixed_name
from colorglove_ros.core.hand.model import DIGITS, HandModel, digit_link_index
from colorglove_ros.core.hand.urdf import calibrated_hand_urdf, tip_link_name, urdf_string
from colorglove_ros.core.hand.urdf_variants import hand_urdf_string


def _joints(text: str) -> dict[str, ET.Element]:
    return {joint.get('name'): joint for joint in ET.fromstring(text).iter('joint')}


def _origin(joint: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    origin = joint.find('origin')
    return (np.array(origin.get('xyz').split(), float),
            np.array(origin.get('rpy').split(), float))


def _rest_transform(text: str, root: str, link: str) -> np.ndarray:
    """root -> link at zero joint angles, composed from the joint origins of the XML."""
    by_child = {j.find('child').get('link'): j for j in ET.fromstring(text).iter('joint')}
    T = np.eye(4)
    while link != root:
        joint = by_child[link]
        xyz, rpy = _origin(joint)
        step = np.eye(4)
        step[:3, :3] = Rotation.from_euler('xyz', rpy).as_matrix()
        step[:3, 3] = xyz
        T = step @ T
        link = joint.find('parent').get('link')
    return T


def test_the_shipped_calibration_gives_the_default_hand() -> None:
    assert calibrated_hand_urdf(CONFIG_DIR / 'calibration.yaml') == urdf_string()


@pytest.mark.parametrize('hand_length_m', [0.16, 0.22])
def test_joint_origins_scale_with_the_hand_length(tmp_path: Path, hand_length_m: float) -> None:
    text = calibrated_hand_urdf(calibration_with_hand_length(tmp_path, hand_length_m),
                                'right_')
    default = _joints(urdf_string())
    joints = _joints(text)
    assert set(joints) == {prefixed_name(name, 'right_') for name in default}
    ratio = hand_length_m / DEFAULT_HAND_LENGTH_M
    moved = 0
    for name, plain in default.items():
        joint = joints[prefixed_name(name, 'right_')]
        xyz, rpy = _origin(joint)
        xyz0, rpy0 = _origin(plain)
        np.testing.assert_allclose(xyz, ratio * xyz0, rtol=1e-9, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(rpy, rpy0, atol=1e-12, err_msg=name)    # angles do not
        if plain.get('type') == 'revolute':
            for bound in ('lower', 'upper'):
                assert float(joint.find('limit').get(bound)) == \
                    float(plain.find('limit').get(bound))
        moved += np.linalg.norm(xyz - xyz0) > 1e-4
    assert moved > 10
    # the flat hand's middle fingertip is hand_length_m from the wrist (the root link's origin)
    tip = _rest_transform(text, hand_root_frame('right_'),
                          prefixed_name(tip_link_name('middle'), 'right_'))
    assert np.linalg.norm(tip[:3, 3]) == pytest.approx(hand_length_m, abs=1e-9)
    assert f'hand length {hand_length_m} m' in text


def test_a_bad_calibration_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match='not found'):
        calibrated_hand_urdf(tmp_path / 'missing.yaml')
    with pytest.raises(CalibrationError, match='not a human hand'):
        calibrated_hand_urdf(calibration_with_hand_length(tmp_path, 0.9))


def _cylinder_lengths(text: str) -> dict[str, float]:
    """Visual cylinder length of every phalanx link of the XML."""
    lengths = {}
    for link in ET.fromstring(text).iter('link'):
        cylinder = link.find('visual/geometry/cylinder')
        if cylinder is not None:
            lengths[link.get('name')] = float(cylinder.get('length'))
    return lengths


def test_link_lengths_follow_the_finger_length_factors(tmp_path: Path) -> None:
    text = calibrated_hand_urdf(calibration_with_hand(tmp_path, UNEVEN_FACTORS, 0.18))
    model = HandModel(0.18, UNEVEN_FACTORS)
    plain = _cylinder_lengths(urdf_string(HandModel(0.18)))
    lengths = _cylinder_lengths(text)
    assert set(lengths) == set(plain) and len(lengths) == 15
    overall = model.scale / HandModel(0.18).scale
    for d, digit in enumerate(DIGITS):
        for k in range(3):
            name = model.link_names[digit_link_index(d, k)]
            assert lengths[name] == pytest.approx(model.link_lengths[digit_link_index(d, k)],
                                                  rel=1e-12)
            assert lengths[name] / plain[name] == pytest.approx(
                UNEVEN_FACTORS[d] * overall, rel=1e-9), name
        tip = _rest_transform(text, HAND_ROOT_LINK, tip_link_name(digit))[:3, 3]
        base = _rest_transform(text, HAND_ROOT_LINK, f'{digit}_base')[:3, 3]
        if digit != 'thumb':     # a flat finger: the tip is its knuckle-to-tip length away
            assert np.linalg.norm(tip - base) == pytest.approx(model.digit_lengths_m[d],
                                                               rel=1e-9)
    # the flat middle fingertip is still the hand length from the wrist
    tip = _rest_transform(text, HAND_ROOT_LINK, tip_link_name('middle'))
    assert np.linalg.norm(tip[:3, 3]) == pytest.approx(0.18, abs=1e-9)
    assert 'finger length factors' in text and 'hand length 0.18 m' in text
    assert 'finger length factors' not in urdf_string(HandModel(0.18))
    # the left hand of the same model mirrors the same lengths
    left = _cylinder_lengths(hand_urdf_string('left', '', model))
    assert left == lengths
