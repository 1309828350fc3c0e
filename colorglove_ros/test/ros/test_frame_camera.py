"""FrameCamera fed by a take function (how the nodes read CameraInfo, when a frame needs it):
every pending CameraInfo is taken and the newest wins, a frame before any gets the waiting
reason, a malformed one the unusable reason, and nothing is taken without use_camera_info.
No rclpy.init: the take function pops a list of messages."""
from __future__ import annotations

from dataclasses import replace

import pytest
from node_fixtures import header
from repo_paths import CONFIG_DIR
from sensor_msgs.msg import CameraInfo

from colorglove_ros.core.camera import PinholeCamera, load_calibration
from colorglove_ros.core.pipeline import NoHand
from colorglove_ros.ros.conversions import camera_to_camera_info_msg
from colorglove_ros.ros.frame_camera import FrameCamera

CAMERA = load_calibration(CONFIG_DIR / 'calibration.yaml').primary


def _info(camera: PinholeCamera) -> CameraInfo:
    return camera_to_camera_info_msg(camera, header(1, frame_id=camera.frame_id))


class _Pending:
    """A take function over the messages that 'arrived', counting its calls."""

    def __init__(self) -> None:
        self.messages: list[CameraInfo] = []
        self.calls = 0

    def __call__(self) -> CameraInfo | None:
        self.calls += 1
        return self.messages.pop(0) if self.messages else None


def _ask(frame_camera: FrameCamera, camera: PinholeCamera = CAMERA) -> PinholeCamera | NoHand:
    return frame_camera.camera_for(camera.width, camera.height, camera.frame_id)


def test_the_newest_pending_camera_info_describes_the_frame() -> None:
    pending = _Pending()
    frame_camera = FrameCamera(CAMERA, take_camera_info=pending)
    waiting = _ask(frame_camera)
    assert isinstance(waiting, NoHand) and waiting.reason == 'camera: waiting for CameraInfo'
    wide = replace(CAMERA, width=CAMERA.width * 2, cx=CAMERA.cx * 2)
    pending.messages = [_info(wide), _info(replace(CAMERA, fx=CAMERA.fx + 1.0)), _info(CAMERA)]
    camera = _ask(frame_camera)
    assert isinstance(camera, PinholeCamera)
    assert (camera.width, camera.fx) == (CAMERA.width, CAMERA.fx)
    assert pending.messages == []
    # none pending: the newest taken so far still describes the next frames
    assert _ask(frame_camera) == camera
    pending.messages = [_info(wide)]
    refused = _ask(frame_camera)
    assert isinstance(refused, NoHand)
    assert refused.reason == (f'camera: image {CAMERA.width}x{CAMERA.height} but CameraInfo '
                              f'says {wide.width}x{CAMERA.height}')
    assert frame_camera.refused == {'waiting for CameraInfo': 1, 'size': 1}


@pytest.mark.parametrize('field, value', [('distortion_model', 'fisheye'), ('k', [0.0] * 9)],
                         ids=['distortion model', 'zero K'])
def test_a_malformed_taken_camera_info_refuses_frames_with_its_reason(field: str,
                                                                     value: object) -> None:
    pending = _Pending()
    frame_camera = FrameCamera(CAMERA, take_camera_info=pending)
    bad = _info(CAMERA)
    setattr(bad, field, value)
    pending.messages = [bad]
    refused = _ask(frame_camera)
    assert isinstance(refused, NoHand)
    assert refused.reason.startswith('camera: unusable CameraInfo: '), refused.reason
    pending.messages = [_info(CAMERA)]      # a good one later: frames are tracked again
    assert isinstance(_ask(frame_camera), PinholeCamera)
    assert frame_camera.refused == {'unusable CameraInfo': 1}


def test_without_use_camera_info_nothing_is_taken() -> None:
    pending = _Pending()
    pending.messages = [_info(replace(CAMERA, width=CAMERA.width * 2))]
    frame_camera = FrameCamera(CAMERA, use_camera_info=False, take_camera_info=pending)
    assert _ask(frame_camera) == CAMERA
    assert pending.calls == 0
