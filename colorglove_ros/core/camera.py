"""Pinhole cameras (intrinsics, distortion, extrinsics) and the calibration YAML."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.yaml_io import load_yaml_mapping

__all__ = [
    'CALIBRATION_VERSION', 'DISTORTION_MODELS', 'CalibrationError', 'PinholeCamera',
    'Calibration', 'load_calibration', 'look_at_extrinsics',
]

CALIBRATION_VERSION = 1
# number of distortion coefficients -> the sensor_msgs/CameraInfo distortion model (OpenCV order)
DISTORTION_MODELS = {5: 'plumb_bob', 8: 'rational_polynomial'}


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
                f'camera {self.name!r}: distortion needs 5 (plumb_bob: k1 k2 p1 p2 k3) or 8 '
                f'(rational_polynomial) coefficients, got shape {size}')

    @property
    def distortion_model(self) -> str:
        """The CameraInfo distortion model of the coefficients (plumb_bob or
        rational_polynomial)."""
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
        return cv2.undistortPoints(pts, self.K, self.distortion, P=self.K).reshape(-1, 2)

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
    """All cameras of a rig plus the user's hand length."""

    cameras: tuple[PinholeCamera, ...]
    hand_length_m: float = 0.19

    @property
    def primary(self) -> PinholeCamera:
        """The camera whose image the lookup runs on."""
        return self.cameras[0]


def _camera_from_dict(entry: dict, where: str) -> PinholeCamera:
    try:
        width, height = int(entry['width']), int(entry['height'])
        fx, fy = float(entry['fx']), float(entry['fy'])
        cx, cy = float(entry['cx']), float(entry['cy'])
        distortion = np.asarray(entry.get('distortion', [0.0] * 5), dtype=float)
        rvec = np.asarray(entry.get('rotation_vector', [0.0, 0.0, 0.0]), dtype=float)
        translation = np.asarray(entry.get('translation', [0.0, 0.0, 0.0]), dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f'{where}: bad or missing camera field: {exc}') from exc
    if width <= 0 or height <= 0 or fx <= 0 or fy <= 0:
        raise CalibrationError(f'{where}: image size and focal lengths must be positive')
    if rvec.shape != (3,) or translation.shape != (3,):
        raise CalibrationError(f'{where}: rotation_vector and translation need 3 values')
    rotation = cv2.Rodrigues(rvec)[0]
    try:
        return PinholeCamera(width, height, fx, fy, cx, cy, distortion, rotation, translation,
                             str(entry.get('name', 'camera')),
                             str(entry.get('frame_id', 'camera_optical_frame')))
    except CalibrationError as exc:
        raise CalibrationError(f'{where}: {exc}') from exc


def load_calibration(path: str | Path) -> Calibration:
    """Read a calibration YAML; raise :class:`CalibrationError` naming what is wrong."""
    path = Path(path)
    data = load_yaml_mapping(path, CalibrationError, 'calibration file')
    if data.get('version') != CALIBRATION_VERSION:
        raise CalibrationError(
            f'calibration file {path} has version {data.get("version")!r}, '
            f'expected {CALIBRATION_VERSION}')
    entries = data.get('cameras')
    if not isinstance(entries, list) or not entries:
        raise CalibrationError(f'calibration file {path} lists no cameras')
    cameras = tuple(_camera_from_dict(e, f'{path}: camera {i}') for i, e in enumerate(entries))
    frame_ids = [camera.frame_id for camera in cameras]
    if len(set(frame_ids)) != len(frame_ids):
        raise CalibrationError(f'{path}: cameras need distinct frame_id values, got {frame_ids}')
    hand_length = float(data.get('hand_length_m', 0.19))
    if not 0.08 < hand_length < 0.35:
        raise CalibrationError(f'{path}: hand_length_m {hand_length} is not a human hand')
    return Calibration(cameras, hand_length)


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
