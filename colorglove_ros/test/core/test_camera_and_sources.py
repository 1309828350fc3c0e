"""Calibration YAML loading and the non-synthetic frame sources."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import CalibrationError, load_calibration, look_at_extrinsics
from colorglove_ros.core.frame_sources import FrameSourceError, open_frame_source

CAMERA = load_calibration(CONFIG_DIR / 'calibration.yaml').primary


def test_shipped_calibrations_load() -> None:
    stereo = load_calibration(CONFIG_DIR / 'calibration_stereo.yaml')
    assert len(stereo.cameras) == 2
    np.testing.assert_allclose(stereo.primary.rotation, np.eye(3))
    # the second camera looks at the centre of the capture volume
    centre = stereo.cameras[1].world_to_camera(np.array([0.0, 0.0, 0.55]))
    np.testing.assert_allclose(centre[:2], 0.0, atol=1e-6)
    assert centre[2] > 0.3


def test_projection_of_the_optical_axis_is_the_principal_point() -> None:
    np.testing.assert_allclose(CAMERA.project(np.array([0.0, 0.0, 2.0])), [CAMERA.cx, CAMERA.cy])
    jac = CAMERA.project_jacobian(np.array([[0.1, -0.05, 0.5]]))
    eps = 1e-7
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = eps
        numeric = (CAMERA.project(np.array([0.1, -0.05, 0.5]) + step)
                   - CAMERA.project(np.array([0.1, -0.05, 0.5]) - step)) / (2 * eps)
        np.testing.assert_allclose(jac[0, :, axis], numeric, rtol=1e-5, atol=1e-3)


def test_in_image_is_the_half_open_pixel_rectangle() -> None:
    w, h = CAMERA.width, CAMERA.height
    pixels = np.array([[0.0, 0.0], [w - 0.01, h - 0.01], [w, 10.0], [10.0, h], [-0.01, 5.0],
                       [5.0, -0.01], [np.nan, 5.0]])
    assert CAMERA.in_image(pixels).tolist() == [True, True, False, False, False, False, False]
    assert CAMERA.in_image(pixels.reshape(7, 1, 2)).shape == (7, 1)


def test_look_at_puts_the_target_on_the_axis() -> None:
    rotation, translation = look_at_extrinsics(np.array([0.3, -0.1, 0.0]), np.array([0, 0, 0.5]))
    target = rotation @ np.array([0, 0, 0.5]) + translation
    np.testing.assert_allclose(target[:2], 0.0, atol=1e-12)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)


@pytest.mark.parametrize('text, message', [
    ('version: 2\ncameras: []', 'version 2'),
    ('version: 1\ncameras: []', 'lists no cameras'),
    ('version: 1\ncameras: [{width: 640}]', 'bad or missing camera field'),
    ('version: 1\ncameras: [{width: 640, height: 480, fx: -1, fy: 1, cx: 0, cy: 0}]', 'positive'),
    ('version: [1\n', 'not valid YAML'),
    ('just text', 'does not hold a mapping'),
    ('version: 1\ncameras: [{width: 640, height: 480, fx: 1, fy: 1, cx: 0, cy: 0, '
     'distortion: [0.1, 0.0, 0.0]}]', r'camera 0: .*distortion needs 5 .* got shape \(3,\)'),
    ('version: 1\ncameras: [{width: 640, height: 480, fx: 1, fy: 1, cx: 0, cy: 0}, '
     '{width: 640, height: 480, fx: 1, fy: 1, cx: 0, cy: 0}]', 'distinct frame_id'),
])
def test_bad_calibration_files_are_refused(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / 'calibration.yaml'
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message):
        load_calibration(path)


def test_missing_calibration_file(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match='not found'):
        load_calibration(tmp_path / 'missing.yaml')


def _frames(count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(count)]


def test_image_folder_source_reads_in_order_and_loops(tmp_path: Path) -> None:
    frames = _frames(3)
    for index, rgb in enumerate(frames):
        cv2.imwrite(str(tmp_path / f'frame_{index:03d}.png'), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    (tmp_path / 'notes.txt').write_text('not an image')
    source = open_frame_source(str(tmp_path), CAMERA, loop=True)
    read = [source.read().image_rgb for _ in range(4)]
    for got, want in zip(read, [*frames, frames[0]], strict=True):
        np.testing.assert_array_equal(got, want)
    once = open_frame_source(str(tmp_path), CAMERA, loop=False)
    assert [once.read() is None for _ in range(4)] == [False, False, False, True]


def test_video_file_source(tmp_path: Path) -> None:
    path = tmp_path / 'clip.avi'
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    flat = [np.full((48, 64, 3), value, np.uint8) for value in (30, 120, 220)]
    for rgb in flat:
        writer.write(rgb)
    writer.release()
    source = open_frame_source(str(path), CAMERA, loop=False)
    means = [source.read().image_rgb.mean() for _ in range(3)]
    np.testing.assert_allclose(means, [30, 120, 220], atol=4)
    assert source.read() is None


@pytest.mark.parametrize('spec, message', [
    ('/dev/video97', 'does not exist'),
    ('no/such/file.mp4', 'neither'),
])
def test_unopenable_sources_raise(spec: str, message: str) -> None:
    with pytest.raises(FrameSourceError, match=message):
        open_frame_source(spec, CAMERA)


def test_empty_folder_raises(tmp_path: Path) -> None:
    with pytest.raises(FrameSourceError, match='holds no images'):
        open_frame_source(str(tmp_path), CAMERA)


@pytest.mark.parametrize('distortion', [[0.1, -0.05, 0.001, 0.002, 0.0],
                                        [0.05, 0.01, -0.01, 0.002]])
def test_distort_pixels_is_the_inverse_of_undistort_pixels(distortion) -> None:
    """plumb_bob (5 coefficients) and equidistant (4): where the camera images ideal pixels,
    undistorted back to them; no distortion: unchanged."""
    from colorglove_ros.core.camera import PinholeCamera

    camera = PinholeCamera(640, 480, 500.0, 510.0, 320.0, 240.0,
                           distortion=np.array(distortion))
    ideal = np.random.default_rng(0).uniform([0, 0], [640, 480], (20, 2))
    seen = camera.distort_pixels(ideal)
    assert np.abs(seen - ideal).max() > 1.0           # the lens moves them
    np.testing.assert_allclose(camera.undistort_pixels(seen), ideal, atol=1e-3)
    plain = PinholeCamera(640, 480, 500.0, 510.0, 320.0, 240.0)
    np.testing.assert_array_equal(plain.distort_pixels(ideal), ideal)
