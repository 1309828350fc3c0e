"""camera_node: publish camera frames (V4L2, video file, image folder or the synthetic renderer)
as ``sensor_msgs/Image`` + ``CameraInfo``; synthetic frames also publish their ground truth.
Health (rate, frames not read or refused) goes to ``/diagnostics``."""
from __future__ import annotations

import sys

from rclpy.node import Node
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.frame_sources import FrameSourceError, open_frame_source
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import camera_to_camera_info_msg
from colorglove_ros.ros.diagnostics import FrameStats
from colorglove_ros.ros.image import array_to_image
from colorglove_ros.ros.nodes.common import (
    PosePublishers,
    calibrated_camera,
    declare,
    declare_calibration_file,
    declare_camera_index,
    run_node,
    startup_errors,
)
from colorglove_ros.ros.nodes.diagnostics_publisher import DiagnosticsPublisher

CAMERA_QOS = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=2,
                        reliability=QoSReliabilityPolicy.RELIABLE)


class CameraNode(Node):
    """Publishes frames at a fixed rate from the configured source."""

    def __init__(self, **kwargs) -> None:
        super().__init__('camera', **kwargs)
        source = declare(self, 'source', 'synthetic',
                         'synthetic | V4L2 index or /dev/videoN | video file | image folder')
        calibration_file = declare_calibration_file(self, 'camera calibration YAML')
        camera_index = declare_camera_index(
            self, 'which camera of the calibration this is (intrinsics, frame_id)')
        rate_hz = declare(self, 'rate_hz', 30.0, 'publish rate, frames per second', 0.1, 240.0)
        seed = declare(self, 'synthetic_seed', 1, 'seed of the synthetic sequence', 0, 2**31 - 1)
        num_frames = declare(self, 'synthetic_frames', 300, 'synthetic sequence length', 1, 10**6)
        loop = declare(self, 'loop', True, 'restart finite sources at their end')
        prerender = declare(self, 'synthetic_prerender', False,
                            'render the whole synthetic sequence at start-up (steady frame rate)')
        self.max_frames = declare(self, 'max_frames', 0,
                                  'stop publishing after this many frames (0 = never)', 0, 10**9)
        with startup_errors('camera_node'):
            calibration = load_calibration(resolve_path(calibration_file))
            if camera_index > 0 and source == 'synthetic':
                raise FrameSourceError(
                    'the synthetic source renders camera 0 only; for synchronised views of '
                    'several cameras play a bag from colorglove_make_bag --calibration')
            self.camera = calibrated_camera(calibration, camera_index, calibration_file)
            self.source = open_frame_source(source, self.camera, seed=seed, num_frames=num_frames,
                                            loop=loop, hand_length_m=calibration.hand_length_m,
                                            prerender=prerender)
        # Reliable publishers match both reliable and best-effort (sensor-data) subscribers.
        self.image_pub = self.create_publisher(Image, 'camera/image_raw', CAMERA_QOS)
        self.info_pub = self.create_publisher(CameraInfo, 'camera/camera_info', CAMERA_QOS)
        self.ground_truth_pub = PosePublishers(self, 'hand/ground_truth/joint_states',
                                               'hand/ground_truth/wrist_pose')
        self.published = 0
        self.stats = FrameStats(what='image')
        self.diagnostics = DiagnosticsPublisher(self, 'frames', self.source.description,
                                                self.stats)
        self.timer = self.create_timer(1.0 / rate_hz, self.publish_frame)
        self.get_logger().info(f'publishing {self.source.description} at {rate_hz:g} Hz')

    def publish_frame(self) -> None:
        """Read one frame and publish it with the current time as stamp."""
        if self.max_frames and self.published >= self.max_frames:
            return
        try:
            frame = self.source.read()
        except FrameSourceError as exc:
            self.get_logger().error(f'frame read failed: {exc}', throttle_duration_sec=1.0)
            self.stats.no_hand(f'frame read failed: {exc}', error=True)
            return
        if frame is None:
            self.get_logger().info('source exhausted; no more frames')
            self.timer.cancel()
            return
        size = frame.image_rgb.shape[1::-1]
        if size != (self.camera.width, self.camera.height):
            reason = (f'size: frame of {size[0]}x{size[1]} does not match the calibrated '
                      f'{self.camera.width}x{self.camera.height} of camera {self.camera.name!r}')
            self.get_logger().error(f'{reason}: not published (fix calibration_file or the '
                                    'source)', throttle_duration_sec=1.0)
            self.stats.no_hand(reason, error=True)
            return
        header = Header(stamp=self.get_clock().now().to_msg(), frame_id=self.camera.frame_id)
        # CameraInfo first (same header): a tracker taking its intrinsics from it has them
        # when the image arrives
        self.info_pub.publish(camera_to_camera_info_msg(self.camera, header))
        self.image_pub.publish(array_to_image(frame.image_rgb, 'rgb8', header))
        if frame.ground_truth_pose is not None:
            self.ground_truth_pub.publish(frame.ground_truth_pose, header)
        self.published += 1
        self.stats.hand()

    def destroy_node(self) -> None:
        """Release the device or file."""
        if hasattr(self, 'source'):
            self.source.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point of ``camera_node``."""
    return run_node(CameraNode, args)


if __name__ == '__main__':
    sys.exit(main())
