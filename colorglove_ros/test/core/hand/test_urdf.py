"""Tests for the generated URDF: parsed by yourdfpy, forward kinematics equal to the model's."""
from __future__ import annotations

import numpy as np
import pytest
import yourdfpy
from repo_paths import PKG_DIR

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.hand.model import DIGITS, FINGER_DOF_NAMES, KEYPOINT_NAMES, HandModel
from colorglove_ros.core.hand.urdf import URDF_PATH, tip_link_name, urdf_string, write_urdf


@pytest.fixture(scope='module', params=[DEFAULT_HAND_LENGTH_M, 0.16])
def pair(request, tmp_path_factory) -> tuple[HandModel, yourdfpy.URDF]:
    model = HandModel(request.param)
    path = write_urdf(tmp_path_factory.mktemp('urdf') / 'hand.urdf', model)
    return model, yourdfpy.URDF.load(str(path), load_meshes=False)


def test_structure(pair) -> None:
    model, urdf = pair
    assert urdf.validate()
    assert urdf.base_link == 'palm'
    assert list(urdf.actuated_joint_names) == list(FINGER_DOF_NAMES)
    for i, name in enumerate(FINGER_DOF_NAMES):
        joint = urdf.joint_map[name]
        assert joint.type == 'revolute'
        assert joint.limit.lower == pytest.approx(model.lower_limits[6 + i], abs=1e-15)
        assert joint.limit.upper == pytest.approx(model.upper_limits[6 + i], abs=1e-15)
    for name in model.link_names:
        assert name in urdf.link_map


@pytest.mark.parametrize('seed', range(5))
def test_forward_kinematics_agree(pair, seed: int) -> None:
    model, urdf = pair
    rng = np.random.default_rng(seed)
    fingers = rng.uniform(model.lower_limits[6:], model.upper_limits[6:])
    urdf.update_cfg(dict(zip(FINGER_DOF_NAMES, fingers, strict=True)))
    q = np.zeros(26)
    q[6:] = fingers
    T = model.link_transforms(q)  # identity global pose: camera frame == palm frame
    for li, name in enumerate(model.link_names):
        Tu = urdf.get_transform(frame_to=name, frame_from='palm')
        assert np.abs(Tu - T[li]).max() < 1e-6
    kp = model.keypoints(q)
    for digit in DIGITS:
        tip = urdf.get_transform(frame_to=tip_link_name(digit), frame_from='palm')[:3, 3]
        assert np.linalg.norm(tip - kp[KEYPOINT_NAMES.index(f'{digit}_tip')]) < 1e-6
    # the configuration is not trivial: fingertips moved away from their rest positions
    kp0 = model.keypoints(np.zeros(26))
    assert np.linalg.norm(kp - kp0, axis=1).max() > 0.02


def test_committed_urdf_is_current() -> None:
    committed = PKG_DIR / URDF_PATH
    assert committed.exists(), 'regenerate with write_urdf(URDF_PATH)'
    assert committed.read_text() == urdf_string()
