"""The standard camera_info YAML of ROS's camera_calibration (plumb_bob, rational_polynomial,
equidistant), rectified input, and an own calibration file naming such a file."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from colorglove_ros.core.camera import (
    CalibrationError,
    camera_from_camera_info,
    load_calibration,
    load_camera_info_yaml,
)

# the layout camera_calibration_parsers writes (writeCalibrationYml)
CAMERA_INFO_YAML = """image_width: 1280
image_height: 720
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [905.1, 0, 641.3, 0, 903.7, 362.9, 0, 0, 1]
distortion_model: {model}
distortion_coefficients:
  rows: 1
  cols: {count}
  data: [{coefficients}]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [880.2, 0, 650.0, 0, 0, 884.5, 360.5, 0, 0, 0, 1, 0]
"""


def write_info(folder: Path, model: str, coefficients: list[float]) -> Path:
    path = folder / f'{model}.yaml'
    path.write_text(CAMERA_INFO_YAML.format(model=model, count=len(coefficients),
                                            coefficients=', '.join(map(str, coefficients))))
    return path


@pytest.mark.parametrize(('model', 'coefficients'), [
    ('plumb_bob', [-0.12, 0.05, 0.001, -0.002, 0.0]),
    ('rational_polynomial', [-0.1, 0.04, 0.001, -0.001, 0.0, 0.02, 0.01, 0.0]),
    ('equidistant', [0.05, -0.01, 0.002, -0.0005]),
])
def test_standard_camera_info_yaml_is_read(tmp_path: Path, model: str,
                                           coefficients: list[float]) -> None:
    camera = load_camera_info_yaml(write_info(tmp_path, model, coefficients))
    assert (camera.width, camera.height) == (1280, 720)
    assert (camera.fx, camera.fy, camera.cx, camera.cy) == (905.1, 903.7, 641.3, 362.9)
    assert camera.distortion_model == model
    np.testing.assert_allclose(camera.distortion, coefficients)
    assert camera.name == 'narrow_stereo'
    # the same file as the calibration: one camera at the origin
    calibration = load_calibration(write_info(tmp_path, model, coefficients))
    assert calibration.primary.distortion_model == model


def test_equidistant_undistorts_as_opencv_fisheye(tmp_path: Path) -> None:
    coefficients = [0.05, -0.01, 0.002, -0.0005]
    camera = load_camera_info_yaml(write_info(tmp_path, 'equidistant', coefficients))
    ideal = np.array([[100.0, 80.0], [640.0, 360.0], [1200.0, 700.0]])
    normalised = np.linalg.solve(camera.K, np.c_[ideal, np.ones(3)].T).T[:, None, :2]
    distorted = cv2.fisheye.distortPoints(normalised, camera.K,
                                          np.asarray(coefficients)).reshape(-1, 2)
    assert np.abs(distorted - ideal).max() > 1.0          # the lens moves the corners
    np.testing.assert_allclose(camera.undistort_pixels(distorted), ideal, atol=1e-3)


def test_rectified_input_uses_p_and_no_distortion(tmp_path: Path) -> None:
    camera = load_camera_info_yaml(write_info(tmp_path, 'plumb_bob', [-0.1, 0.0, 0, 0, 0]),
                                   rectified=True)
    assert (camera.fx, camera.fy, camera.cx, camera.cy) == (880.2, 884.5, 650.0, 360.5)
    assert not np.any(camera.distortion)


def test_own_calibration_names_a_camera_info_file(tmp_path: Path) -> None:
    write_info(tmp_path, 'plumb_bob', [-0.1, 0.02, 0, 0, 0])
    own = tmp_path / 'calibration.yaml'
    own.write_text('version: 1\nhand_length_m: 0.18\ncameras:\n'
                   '  - camera_info_file: plumb_bob.yaml\n    frame_id: usb_cam_optical\n'
                   '    translation: [0.1, 0.0, 0.0]\n'
                   '  - camera_info_file: plumb_bob.yaml\n    rectified: true\n'
                   '    frame_id: cam2_optical\n')
    calibration = load_calibration(own)
    assert calibration.hand_length_m == 0.18
    first, second = calibration.cameras
    assert first.frame_id == 'usb_cam_optical' and first.fx == 905.1
    np.testing.assert_allclose(first.translation, [0.1, 0.0, 0.0])
    assert second.fx == 880.2 and not np.any(second.distortion)


@pytest.mark.parametrize(('model', 'coefficients', 'message'), [
    ('fisheye62', [0.0] * 8, 'not supported'),
    ('plumb_bob', [0.1, 0.2, 0.0], 'needs 5'),
    ('equidistant', [float('nan'), 0.0, 0.0, 0.0], 'D'),
])
def test_bad_camera_info_is_refused(tmp_path: Path, model: str, coefficients: list[float],
                                    message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        load_camera_info_yaml(write_info(tmp_path, model, coefficients))


def test_camera_from_message_fields_refuses_nan_intrinsics() -> None:
    with pytest.raises(CalibrationError, match='K must be finite'):
        camera_from_camera_info(640, 480, [float('nan'), 0, 320, 0, 600, 240, 0, 0, 1],
                                [0.0] * 5, 'plumb_bob')
