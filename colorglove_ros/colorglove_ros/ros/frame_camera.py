"""The camera model of each incoming frame: from the newest ``sensor_msgs/CameraInfo`` of the
camera (any driver, any resolution) or from the calibration YAML, and the refusal of a frame
whose size or frame_id does not match it (never tracked with the wrong intrinsics). No rclpy
import: the nodes feed it messages (or a function taking them), so it is unit-testable in one
process."""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import replace

from sensor_msgs.msg import CameraInfo

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.pipeline import NoHand
from colorglove_ros.ros.conversions import camera_from_camera_info_msg

__all__ = ['CAMERA_REFUSAL_PREFIX', 'FrameCamera', 'REFUSAL_KINDS']

REFUSAL_KINDS = ('waiting for CameraInfo', 'unusable CameraInfo', 'size', 'frame_id')
"""Keys of :attr:`FrameCamera.refused` (why frames were refused, with their counts)."""
CAMERA_REFUSAL_PREFIX = 'camera: '
"""How the 'no hand' reason of every refusal starts."""


class FrameCamera:
    """Which camera model a frame of a given size and frame_id is seen with.

    With ``use_camera_info`` the model is the newest CameraInfo given to
    :meth:`set_camera_info` (a fixed camera: its newest message describes every frame); a
    frame is accepted only when its width, height and frame_id equal the CameraInfo's. Without,
    the model is ``calibrated`` (its camera of the calibration YAML) and a frame of another size
    is refused (and, with ``calibrated_frame_id``, one of another frame_id than the calibrated
    camera's). The returned camera keeps the calibrated camera's name (status lines) and
    extrinsics (identity for camera 0, the calibration's for the others). Refusals are
    :class:`NoHand` ``'camera: ...'`` and are counted per kind in :attr:`refused`.

    ``take_camera_info``, when given, returns the next CameraInfo that has arrived (None when
    none is pending): :meth:`camera_for` first takes every pending one (the newest wins), so a
    node reads CameraInfo when a frame needs it instead of on every message's arrival.
    """

    def __init__(self, calibrated: PinholeCamera, use_camera_info: bool = True, *,
                 rectified: bool = False, calibrated_frame_id: bool = False,
                 take_camera_info: Callable[[], CameraInfo | None] | None = None) -> None:
        self.calibrated = calibrated
        self.take_camera_info = take_camera_info
        self.use_camera_info = bool(use_camera_info)
        self.rectified = bool(rectified)
        self.calibrated_frame_id = bool(calibrated_frame_id)
        self.refused: Counter[str] = Counter()
        self._info_key: tuple | None = None
        self._info_camera: PinholeCamera | None = None
        self._info_frame_id = ''
        self._info_error = ''

    @property
    def camera_info_camera(self) -> PinholeCamera | None:
        """The camera of the newest usable CameraInfo (None before one, or if unusable)."""
        return self._info_camera

    def set_camera_info(self, msg: CameraInfo) -> None:
        """Keep the newest CameraInfo (converted once per distinct content)."""
        key = (int(msg.width), int(msg.height), str(msg.header.frame_id),
               str(msg.distortion_model), tuple(msg.k), tuple(msg.d), tuple(msg.p))
        if key == self._info_key:
            return
        self._info_key = key
        self._info_frame_id = key[2]
        try:
            camera = camera_from_camera_info_msg(msg, rectified=self.rectified)
            self._info_camera = replace(camera, name=self.calibrated.name,
                                        rotation=self.calibrated.rotation,
                                        translation=self.calibrated.translation)
            self._info_error = ''
        except (ColorGloveError, ValueError) as exc:
            self._info_camera = None
            self._info_error = str(exc)

    def take_pending(self) -> None:
        """Take every CameraInfo pending on ``take_camera_info`` and keep the newest."""
        if self.take_camera_info is None:
            return
        newest = None
        while (msg := self.take_camera_info()) is not None:
            newest = msg
        if newest is not None:
            self.set_camera_info(newest)

    def _refuse(self, kind: str, detail: str) -> NoHand:
        self.refused[kind] += 1
        return NoHand(f'{CAMERA_REFUSAL_PREFIX}{detail}', warn=True)

    def camera_for(self, width: int, height: int, frame_id: str) -> PinholeCamera | NoHand:
        """The camera model of a ``width`` x ``height`` frame in ``frame_id``, or the reason
        it is refused (see the class docstring)."""
        if self.use_camera_info:
            self.take_pending()
        if not self.use_camera_info:
            camera, source = self.calibrated, 'calibration'
        elif self._info_key is None:
            return self._refuse('waiting for CameraInfo', 'waiting for CameraInfo')
        elif self._info_camera is None:
            return self._refuse('unusable CameraInfo',
                                f'unusable CameraInfo: {self._info_error}')
        else:
            camera, source = self._info_camera, 'CameraInfo'
        if (int(width), int(height)) != (camera.width, camera.height):
            return self._refuse('size', f'image {width}x{height} but {source} says '
                                        f'{camera.width}x{camera.height}')
        if self.use_camera_info and frame_id != self._info_frame_id:
            return self._refuse('frame_id', f'frame_id {frame_id!r} != CameraInfo frame_id '
                                            f'{self._info_frame_id!r}')
        if not self.use_camera_info and self.calibrated_frame_id \
                and frame_id != camera.frame_id:
            return self._refuse('frame_id', f'frame_id {frame_id!r} != calibrated frame_id '
                                            f'{camera.frame_id!r}')
        return camera
