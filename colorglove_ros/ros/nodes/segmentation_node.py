"""segmentation_node: camera ``Image`` -> ``HandObservation`` (per-pixel glove colour
classification, mean-shift crop, 40x40 tiny label image, patch blobs).

A frame is segmented only when its camera model is known: with ``use_camera_info`` (default)
the newest ``camera/camera_info`` must have the image's size and frame_id, else camera
``camera_index`` of ``calibration_file`` its size; other frames give 'camera: ...'
observations without a hand. An extra camera's segmentation_node runs in the camera's
namespace ``NS`` (``NS/camera/image_raw``, ``NS/camera/camera_info`` -> ``NS/hand/observation``,
which ik_node's ``extra_observation_topics`` names)."""
from __future__ import annotations

import sys
import traceback

import numpy as np
from colorglove_msgs.msg import HandObservation
from rclpy.node import Node
from sensor_msgs.msg import Image

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.pipeline import NoHand, bad_image, segment_frame
from colorglove_ros.core.segmentation.color_model import ColorCalibrationError
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.core.segmentation.types import Observation
from colorglove_ros.core.validation import validate_image_size
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import observation_to_msg
from colorglove_ros.ros.image import ImageEncodingError, array_to_image, image_to_rgb8
from colorglove_ros.ros.nodes.common import (
    LATEST_IMAGE,
    OBSERVATION_TOPIC,
    StartupError,
    calibrated_camera,
    declare,
    declare_calibration_file,
    declare_camera_index,
    declare_frame_camera,
    run_node,
    startup_errors,
)

# Label image -> colours for the debug image: background black, glove colours as printed.
DEBUG_PALETTE = np.vstack([[0, 0, 0], GLOVE_PALETTE_RGB]).astype(np.uint8)


class SegmentationNode(Node):
    """Segments every camera frame into a glove observation."""

    def __init__(self, **kwargs) -> None:
        super().__init__('segmentation', **kwargs)
        config = declare(self, 'color_calibration_file', 'config/color_calibration.yaml',
                         'colour calibration config YAML (calibration file + segmenter settings)')
        self.publish_debug = declare(self, 'publish_debug_image', False,
                                     'also publish the per-pixel classification as an image')
        calibration_file = declare_calibration_file(
            self, 'camera calibration YAML (camera camera_index: the image size expected when '
                  'use_camera_info is false)')
        camera_index = declare_camera_index(
            self, 'which camera of calibration_file this node segments (used when '
                  'use_camera_info is false)')
        try:
            self.segmenter = load_segmenter(config)
        except (ColorCalibrationError, OSError, ValueError) as exc:
            raise StartupError(f'segmentation_node cannot start: {exc}') from exc
        with startup_errors('segmentation_node', ValueError):
            calibration = load_calibration(resolve_path(calibration_file))
            camera = calibrated_camera(calibration, camera_index, calibration_file)
        self.frame_camera = declare_frame_camera(self, camera)
        self.publisher = self.create_publisher(HandObservation, OBSERVATION_TOPIC, 10)
        self.debug_publisher = self.create_publisher(Image, 'hand/segmentation_debug', 2)
        self.create_subscription(Image, 'camera/image_raw', self.on_image, LATEST_IMAGE)
        self.get_logger().info(f'colour calibration from {config}')

    def _no_hand(self, image: Image, reason: str) -> None:
        self.publisher.publish(HandObservation(header=image.header, hand_found=False,
                                               status=reason, image_width=image.width,
                                               image_height=image.height))

    def _segment(self, image: Image) -> Observation | NoHand:
        """The frame's observation (``core.pipeline.segment_frame``), or 'no hand' for an
        image that cannot be decoded or whose camera model is not known."""
        try:
            validate_image_size(image.width, image.height, error=ImageEncodingError)
            rgb = image_to_rgb8(image)
        except ImageEncodingError as exc:
            return bad_image(exc)
        camera = self.frame_camera.camera_for(image.width, image.height, image.header.frame_id)
        if isinstance(camera, NoHand):
            return camera
        return segment_frame(self.segmenter, rgb, keep_labels=self.publish_debug)

    def on_image(self, image: Image) -> None:
        """Segment one frame; bad frames, and observations that fail their own checks, are
        reported as 'no hand' with the reason. No message stops the node."""
        try:
            observation = self._segment(image)
            if not isinstance(observation, NoHand):
                msg = observation_to_msg(observation, image.header)
        except Exception as exc:   # last line of defence: a frame must never stop the node
            self.get_logger().error(f'segmentation failed: {exc!r}\n{traceback.format_exc()}',
                                    throttle_duration_sec=1.0)
            self._no_hand(image, f'segmentation failed: {exc!r}')
            return
        if isinstance(observation, NoHand):
            if observation.warn:
                self.get_logger().warn(observation.reason, throttle_duration_sec=1.0)
            self._no_hand(image, observation.reason)
            return
        self.publisher.publish(msg)
        if self.publish_debug and observation.label_image is not None:
            self.debug_publisher.publish(array_to_image(DEBUG_PALETTE[observation.label_image],
                                                        'rgb8', image.header))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``segmentation_node``."""
    return run_node(SegmentationNode, args)


if __name__ == '__main__':
    sys.exit(main())
