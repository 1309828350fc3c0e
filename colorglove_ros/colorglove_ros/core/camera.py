"""Pinhole cameras (intrinsics, distortion, extrinsics) and the calibration YAML."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M, HAND_LENGTH_RANGE_M
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import (
    NOMINAL_FINGER_LENGTH_FACTORS,
    check_finger_length_factors,
)
from colorglove_ros.core.validation import (
    MAX_IMAGE_SIDE,
    check_array,
    check_known_keys,
    check_number,
)
from colorglove_ros.core.yaml_io import load_yaml_mapping

__all__ = [
    'camera_from_camera_info', 'load_camera_info_yaml',
    'CALIBRATION_VERSION', 'DISTORTION_MODELS', 'CalibrationError', 'PinholeCamera',
    'Calibration', 'load_calibration', 'look_at_extrinsics',
]

CALIBRATION_VERSION = 1
# number of distortion coefficients -> the sensor_msgs/CameraInfo distortion model (OpenCV order;
# equidistant is OpenCV's fisheye model, k1..k4)
DISTORTION_MODELS = {5: 'plumb_bob', 8: 'rational_polynomial', 4: 'equidistant'}
# the standard camera_info YAML of camera_calibration_parsers (camera_calibration's output)
CAMERA_INFO_YAML_KEYS = ('image_width', 'image_height', 'camera_matrix')


class CalibrationError(ColorGloveError):
    """A calibration file is missing, malformed or of another version."""


@dataclass(frozen=True)
class PinholeCamera:
    """A calibrated camera. Extrinsics map world points into the optical frame:
    ``p_cam = R @ p_world + t``."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    name: str = 'camera'
    frame_id: str = 'camera_optical_frame'

    def __post_init__(self) -> None:
        size = np.shape(self.distortion)
        if len(size) != 1 or size[0] not in DISTORTION_MODELS:
            raise CalibrationError(
                f'camera {self.name!r}: distortion needs 5 (plumb_bob: k1 k2 p1 p2 k3), 8 '
                f'(rational_polynomial) or 4 (equidistant: k1..k4) coefficients, got shape '
                f'{size}')

    @property
    def distortion_model(self) -> str:
        """The CameraInfo distortion model of the coefficients (plumb_bob, rational_polynomial
        or equidistant)."""
        return DISTORTION_MODELS[len(self.distortion)]

    def camera_info_fields(self) -> dict:
        """The fields of a ``sensor_msgs/CameraInfo`` for this camera as plain numbers:
        size, distortion model and D, K, R (identity: no rectification), P = [K | 0]."""
        projection = np.zeros((3, 4))
        projection[:, :3] = self.K
        return {'height': int(self.height), 'width': int(self.width),
                'distortion_model': self.distortion_model,
                'd': [float(v) for v in self.distortion],
                'k': [float(v) for v in self.K.ravel()],
                'r': [float(v) for v in np.eye(3).ravel()],
                'p': [float(v) for v in projection.ravel()]}

    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the intrinsic matrix is K everywhere)
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def world_to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """Map (..., 3) world points into this camera's optical frame."""
        return points_world @ self.rotation.T + self.translation

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        """Project (..., 3) optical-frame points to (..., 2) pixels (no distortion)."""
        z = points_camera[..., 2:3]
        xy = points_camera[..., :2] / z
        return xy * np.array([self.fx, self.fy]) + np.array([self.cx, self.cy])

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """Whether each of (..., 2) pixels lies inside the image, x in [0, width) and y in
        [0, height) (NaN: no)."""
        px = np.asarray(pixels, dtype=float)
        return ((px[..., 0] >= 0) & (px[..., 0] < self.width) & (px[..., 1] >= 0)
                & (px[..., 1] < self.height))

    def project_jacobian(self, points_camera: np.ndarray) -> np.ndarray:
        """d(pixel)/d(point) for (N, 3) optical-frame points: (N, 2, 3)."""
        x, y, z = points_camera[:, 0], points_camera[:, 1], points_camera[:, 2]
        jac = np.zeros((len(points_camera), 2, 3))
        jac[:, 0, 0] = self.fx / z
        jac[:, 0, 2] = -self.fx * x / z**2
        jac[:, 1, 1] = self.fy / z
        jac[:, 1, 2] = -self.fy * y / z**2
        return jac

    def undistort_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Remove lens distortion from (N, 2) measured pixels (identity if none)."""
        if not np.any(self.distortion):
            return np.asarray(pixels, dtype=float)
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        if self.distortion_model == 'equidistant':
            return cv2.fisheye.undistortPoints(pts, self.K, self.distortion,
                                               P=self.K).reshape(-1, 2)
        return cv2.undistortPoints(pts, self.K, self.distortion, P=self.K).reshape(-1, 2)

    def distort_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Add lens distortion to (N, 2) ideal pixels (:meth:`project`'s): where the camera
        images them; the inverse of :meth:`undistort_pixels` (identity if no distortion)."""
        if not np.any(self.distortion):
            return np.asarray(pixels, dtype=float)
        ideal = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        xy = (ideal - np.array([self.cx, self.cy])) / np.array([self.fx, self.fy])
        if self.distortion_model == 'equidistant':
            return cv2.fisheye.distortPoints(xy.reshape(-1, 1, 2), self.K,
                                             self.distortion).reshape(-1, 2)
        rays = np.column_stack([xy, np.ones(len(xy))])
        seen, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), self.K, self.distortion)
        return seen.reshape(-1, 2)

    def to_dict(self) -> dict:
        """The YAML form of this camera (see ``config/calibration.yaml``)."""
        rvec = cv2.Rodrigues(np.asarray(self.rotation, dtype=np.float64))[0].ravel()
        return {
            'name': self.name, 'frame_id': self.frame_id,
            'width': int(self.width), 'height': int(self.height),
            'fx': float(self.fx), 'fy': float(self.fy), 'cx': float(self.cx), 'cy': float(self.cy),
            'distortion': [float(v) for v in self.distortion],
            'rotation_vector': [float(v) for v in rvec],
            'translation': [float(v) for v in self.translation],
        }


@dataclass(frozen=True)
class Calibration:
    """All cameras of a rig plus the user's hand: its length and finger length factors
    (thumb, index, middle, ring, little; ``core.hand.model.HandModel``, which
    ``calibrated_hand_model`` builds from this)."""

    cameras: tuple[PinholeCamera, ...]
    hand_length_m: float = DEFAULT_HAND_LENGTH_M
    finger_length_factors: tuple[float, ...] = NOMINAL_FINGER_LENGTH_FACTORS

    @property
    def primary(self) -> PinholeCamera:
        """The camera whose image the lookup runs on."""
        return self.cameras[0]


MAX_DISTORTION_COEFFICIENT = 1e4
"""Larger lens distortion coefficients are no lens's (a corrupt or mistyped value)."""
MAX_CAMERA_DISTANCE_M = 100.0
"""Cameras of one rig farther apart than this cannot watch one hand."""
CAMERA_KEYS = frozenset({'name', 'frame_id', 'width', 'height', 'fx', 'fy', 'cx', 'cy',
                         'distortion', 'rotation_vector', 'translation', 'camera_info_file',
                         'rectified'})
"""The fields of one camera entry of the own calibration format."""
CALIBRATION_KEYS = frozenset({'version', 'hand_length_m', 'finger_length_factors', 'cameras'})
"""The top-level fields of the own calibration format."""


def _camera_from_dict(entry: dict, where: str) -> PinholeCamera:
    if not isinstance(entry, dict):
        raise CalibrationError(f'{where}: a camera must be a mapping, got {entry!r}')
    check_known_keys(f'{where}: camera', entry, CAMERA_KEYS, error=CalibrationError)
    missing = [key for key in ('width', 'height', 'fx', 'fy', 'cx', 'cy') if key not in entry]
    if missing:
        raise CalibrationError(f'{where}: bad or missing camera field(s): {missing} missing')

    def number(key: str, **bounds) -> float:
        return check_number(f'{where}: {key}', entry[key], error=CalibrationError, **bounds)

    # finite, positive focal lengths; principal point within (a margin around) the image
    width = int(number('width', low=1, high=MAX_IMAGE_SIDE, integer=True))
    height = int(number('height', low=1, high=MAX_IMAGE_SIDE, integer=True))
    fx = float(number('fx', low=0.0, low_open=True, high=100.0 * max(width, height)))
    fy = float(number('fy', low=0.0, low_open=True, high=100.0 * max(width, height)))
    cx = float(number('cx', low=-width, high=2.0 * width))
    cy = float(number('cy', low=-height, high=2.0 * height))

    def vector(key: str, default: list[float], shape: tuple[int | None, ...],
               limit: float) -> np.ndarray:
        value = entry.get(key, default)
        if not isinstance(value, (list, tuple)):
            raise CalibrationError(f'{where}: {key} must be a list of numbers, got {value!r}')
        return check_array(f'{where}: {key}', value, shape=shape, low=-limit, high=limit,
                           error=CalibrationError).astype(float)

    distortion = vector('distortion', [0.0] * 5, (None,), MAX_DISTORTION_COEFFICIENT)
    rvec = vector('rotation_vector', [0.0, 0.0, 0.0], (3,), 2.0 * np.pi)
    translation = vector('translation', [0.0, 0.0, 0.0], (3,), MAX_CAMERA_DISTANCE_M)
    rotation = cv2.Rodrigues(rvec)[0]
    try:
        return PinholeCamera(width, height, fx, fy, cx, cy, distortion, rotation, translation,
                             str(entry.get('name', 'camera')),
                             str(entry.get('frame_id', 'camera_optical_frame')))
    except CalibrationError as exc:
        raise CalibrationError(f'{where}: {exc}') from exc


def _camera_entry(entry: object, path: Path, where: str) -> PinholeCamera:
    """One camera of the own format, its intrinsics inline or from a ``camera_info_file``."""
    if not isinstance(entry, dict) or 'camera_info_file' not in entry:
        return _camera_from_dict(entry, where)
    info_path = Path(str(entry['camera_info_file'])).expanduser()
    if not info_path.is_absolute():
        info_path = path.parent / info_path
    camera = load_camera_info_yaml(info_path, rectified=bool(entry.get('rectified', False)))
    merged = {**camera.to_dict(), **{k: v for k, v in entry.items()
                                     if k in ('name', 'frame_id', 'rotation_vector',
                                              'translation')}}
    return _camera_from_dict(merged, where)


def camera_from_camera_info(width: int, height: int, k: Sequence[float], d: Sequence[float],
                            distortion_model: str, p: Sequence[float] | None = None, *,
                            rectified: bool = False, name: str = 'camera',
                            frame_id: str = 'camera_optical_frame', where: str = 'CameraInfo'
                            ) -> PinholeCamera:
    """A camera from the fields of a ``sensor_msgs/CameraInfo`` (or its YAML file).

    ``rectified``: the images are ``image_rect`` (image_proc's output), so the intrinsics are
    the projection matrix P's and there is no distortion left, as image_geometry does.
    """
    k_matrix = check_array(f'{where}: K', k, shape=(9,), error=CalibrationError).reshape(3, 3)
    if rectified:
        if p is None:
            raise CalibrationError(f'{where}: rectified images need the projection matrix P')
        intrinsics = check_array(f'{where}: P', p, shape=(12,),
                                 error=CalibrationError).reshape(3, 4)[:, :3]
        coefficients = np.zeros(5)
    else:
        intrinsics = k_matrix
        model = str(distortion_model)
        expected = {m: n for n, m in DISTORTION_MODELS.items()}
        if model not in expected:
            raise CalibrationError(f'{where}: distortion model {model!r} is not supported '
                                   f'(supported: {", ".join(expected)}; or rectified images)')
        coefficients = check_array(f'{where}: D', d, error=CalibrationError).astype(float)
        if coefficients.size == 0:
            coefficients = np.zeros(expected[model])
        if coefficients.shape != (expected[model],):
            raise CalibrationError(f'{where}: {model} needs {expected[model]} distortion '
                                   f'coefficients, got {coefficients.size}')
    entry = {'width': width, 'height': height, 'fx': intrinsics[0, 0], 'fy': intrinsics[1, 1],
             'cx': intrinsics[0, 2], 'cy': intrinsics[1, 2],
             'distortion': [float(v) for v in coefficients], 'name': name,
             'frame_id': frame_id}
    return _camera_from_dict(entry, where)


def _yaml_matrix(data: dict, key: str, shape: tuple[int, int], where: str) -> list[float]:
    block = data.get(key)
    if not isinstance(block, dict) or 'data' not in block:
        raise CalibrationError(f'{where}: {key} must be a mapping with rows, cols and data')
    if (block.get('rows'), block.get('cols')) != shape and key != 'distortion_coefficients':
        raise CalibrationError(f'{where}: {key} must be {shape[0]}x{shape[1]}, got '
                               f'{block.get("rows")}x{block.get("cols")}')
    if not isinstance(block['data'], list):
        raise CalibrationError(f'{where}: {key}.data must be a list of numbers')
    return block['data']


def load_camera_info_yaml(path: str | Path, *, rectified: bool = False,
                          frame_id: str = 'camera_optical_frame') -> PinholeCamera:
    """A camera from the standard camera_info YAML that ROS's ``camera_calibration`` writes
    (camera_calibration_parsers: ``image_width``, ``camera_matrix {rows, cols, data}``,
    ``distortion_model``, ``distortion_coefficients``, ``projection_matrix``, ...)."""
    path = Path(path)
    data = load_yaml_mapping(path, CalibrationError, 'camera_info file')
    where = f'camera_info file {path}'
    missing = [key for key in (*CAMERA_INFO_YAML_KEYS, 'distortion_model') if key not in data]
    if missing:
        raise CalibrationError(f'{where}: missing {missing}')
    distortion = data.get('distortion_coefficients', {'rows': 1, 'cols': 0, 'data': []})
    return camera_from_camera_info(
        data['image_width'], data['image_height'],
        _yaml_matrix(data, 'camera_matrix', (3, 3), where),
        _yaml_matrix({'distortion_coefficients': distortion}, 'distortion_coefficients',
                     (1, 0), where),
        data['distortion_model'],
        _yaml_matrix(data, 'projection_matrix', (3, 4), where)
        if 'projection_matrix' in data else None,
        rectified=rectified, name=str(data.get('camera_name', 'camera')), frame_id=frame_id,
        where=where)


def load_calibration(path: str | Path) -> Calibration:
    """Read a calibration YAML; raise :class:`CalibrationError` naming what is wrong.

    Besides this package's own format (``version: 1``, ``hand_length_m``, optional
    ``finger_length_factors``, a list of cameras), a standard camera_info YAML from
    ``camera_calibration`` is read as one camera at the origin with the default hand; a camera
    entry of the own format may also name one with ``camera_info_file`` (and
    ``rectified: true`` for ``image_rect`` input), keeping its extrinsics, name and frame_id in
    the own file.
    """
    path = Path(path)
    data = load_yaml_mapping(path, CalibrationError, 'calibration file')
    if all(key in data for key in CAMERA_INFO_YAML_KEYS):
        return Calibration((load_camera_info_yaml(path),), DEFAULT_HAND_LENGTH_M)
    if data.get('version') != CALIBRATION_VERSION:
        raise CalibrationError(
            f'calibration file {path} has version {data.get("version")!r}, '
            f'expected {CALIBRATION_VERSION}')
    check_known_keys(f'calibration file {path}', data, CALIBRATION_KEYS, error=CalibrationError)
    entries = data.get('cameras')
    if not isinstance(entries, list) or not entries:
        raise CalibrationError(f'calibration file {path} lists no cameras')
    cameras = tuple(_camera_entry(e, path, f'{path}: camera {i}') for i, e in enumerate(entries))
    frame_ids = [camera.frame_id for camera in cameras]
    if len(set(frame_ids)) != len(frame_ids):
        raise CalibrationError(f'{path}: cameras need distinct frame_id values, got {frame_ids}')
    hand_length = check_number(f'{path}: hand_length_m',
                               data.get('hand_length_m', DEFAULT_HAND_LENGTH_M),
                               error=CalibrationError)
    if not HAND_LENGTH_RANGE_M[0] < hand_length < HAND_LENGTH_RANGE_M[1]:
        raise CalibrationError(f'{path}: hand_length_m {hand_length} is not a human hand')
    factors = check_finger_length_factors(
        f'{path}: finger_length_factors',
        data.get('finger_length_factors', list(NOMINAL_FINGER_LENGTH_FACTORS)),
        error=CalibrationError)
    return Calibration(cameras, hand_length, factors)


def look_at_extrinsics(eye: np.ndarray, target: np.ndarray,
                       down: tuple[float, float, float] = (0.0, 1.0, 0.0),
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation (world -> optical frame) of a camera at ``eye`` looking
    at ``target``, with image rows running along ``down``."""
    z_axis = np.asarray(target, float) - np.asarray(eye, float)
    z_axis /= np.linalg.norm(z_axis)
    x_axis = np.cross(np.asarray(down, float), z_axis)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    rotation = np.stack([x_axis, y_axis, z_axis])
    return rotation, -rotation @ np.asarray(eye, float)
