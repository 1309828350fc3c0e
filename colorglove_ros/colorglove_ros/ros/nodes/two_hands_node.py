"""two_hands_node: camera ``Image`` -> a left and a right gloved hand at once, each published
under its own namespace: ``hand/<hand>/joint_states`` (joint names ``<hand>_<joint>``),
``hand/<hand>/wrist_pose`` and ``hand/<hand>/tracking_status`` (``tracking: ...`` or
``no hand: <reason>``), plus the TF ``camera -> <hand>_palm`` where tf2_msgs is installed.

A thin shell over ``core.hands.TwoHandPipeline`` (segmentation of each glove region, lookups as
seen and mirrored, handedness from the evidence and continuity, one tracker per hand): a hand
whose handedness is not decided in a frame, or that is not found, gets no pose that frame and
its status says why. One process, one camera (camera 0 of ``calibration_file``, whose image
size frames must have)."""
from __future__ import annotations

import sys
import traceback

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import Header, String

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.hand.frames import hand_root_frame
from colorglove_ros.core.hand.glove import calibrated_hand
from colorglove_ros.core.hand.handedness import HANDS
from colorglove_ros.core.hands import (
    DEFAULT_THREADS,
    HandOutcome,
    TwoHandPipeline,
    slot_lookups,
)
from colorglove_ros.core.lookup.database import (
    check_hand_length,
    load_database,
    start_reading_into_page_cache,
)
from colorglove_ros.core.pipeline import Tracked
from colorglove_ros.core.segmentation.segmenter import load_segmenter
from colorglove_ros.core.tracking.config import load_ik_config
from colorglove_ros.core.tracking.tracker import HandTracker
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import stamp_to_seconds, wrist_pose_to_tf_msg
from colorglove_ros.ros.frame_camera import CAMERA_REFUSAL_PREFIX
from colorglove_ros.ros.image import ImageEncodingError, image_to_rgb8
from colorglove_ros.ros.image_codec import SerializedImage, image_from_cdr
from colorglove_ros.ros.nodes.common import (
    LATEST_IMAGE,
    PosePublishers,
    declare,
    declare_calibration_file,
    declare_database,
    declare_opencv_threads,
    run_node,
    startup_errors,
)

__all__ = ['TwoHandsNode', 'hand_topic', 'main']

IMAGE_TOPIC = 'camera/image_raw'


def hand_topic(hand: str, name: str) -> str:
    """The topic ``name`` (e.g. 'joint_states') of ``hand``: ``hand/<hand>/<name>``."""
    return f'hand/{hand}/{name}'


class TwoHandsNode(Node):
    """Tracks a left and a right glove in one camera's frames."""

    def __init__(self, **kwargs) -> None:
        super().__init__('two_hands', **kwargs)
        color_config = declare(self, 'color_calibration_file', 'config/color_calibration.yaml',
                               'colour calibration config YAML (calibration + segmenter)')
        calibration_file = declare_calibration_file(
            self, 'camera calibration YAML (camera 0: the camera; the hand\'s measurements)')
        ik_config = declare(self, 'ik_config', 'config/ik.yaml', 'IK settings and covariances')
        threads = declare(self, 'threads', DEFAULT_THREADS,
                          '2: the two glove regions segmented and looked up, and the two hands '
                          'tracked, on two threads; 1: one after the other', 1, 2)
        declare_opencv_threads(self)
        with startup_errors('two_hands_node', ValueError):
            calibration = load_calibration(resolve_path(calibration_file))
            database_path = declare_database(self)
            database = load_database(database_path)
            # the memory-mapped arrays mapped into this process and read into the page
            # cache in the background: else the first lookups wait for page faults (and, from a
            # cold cache, for random disk reads)
            self.page_cache_reader = start_reading_into_page_cache(database_path, database)
            check_hand_length(database.build, calibration.hand_length_m, calibration_file,
                              database_path)
            segmenter = load_segmenter(color_config)
            config = load_ik_config(resolve_path(ik_config))
            model, mesh, glove = calibrated_hand(calibration, database.build.glove_seed)
            lookups = slot_lookups(database, threads)
        self.camera = calibration.primary
        trackers = {h: HandTracker(model, mesh, [self.camera], config, glove) for h in HANDS}
        self.pipeline = TwoHandPipeline(segmenter, lookups, self.camera, trackers)
        self.frames = {h: hand_root_frame(f'{h}_') for h in HANDS}
        self.poses = {h: PosePublishers(self, hand_topic(h, 'joint_states'),
                                        hand_topic(h, 'wrist_pose'), f'{h}_') for h in HANDS}
        self.status = {h: self.create_publisher(String, hand_topic(h, 'tracking_status'), 10)
                       for h in HANDS}
        self.tf_pub = self._tf_publisher()
        # serialized: the pixels are read in place, not converted to a Python message
        self.create_subscription(Image, IMAGE_TOPIC, self.on_serialized_image, LATEST_IMAGE,
                                 raw=True)
        self.get_logger().info(f'two hands: database {database_path} ({len(database)} entries); '
                               f'images on {self.resolve_topic_name(IMAGE_TOPIC)}')

    def destroy_node(self) -> None:
        """Stop the pipeline's worker thread, then the node."""
        self.pipeline.close()
        super().destroy_node()

    def _tf_publisher(self):
        """A /tf publisher for camera -> ``<hand>_palm``, when tf2_msgs is installed."""
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            return None
        return self.create_publisher(TFMessage, '/tf', 10)

    def on_serialized_image(self, data: bytes) -> None:
        """Track both hands in one frame received serialized (``ros.image_codec.image_from_cdr``:
        its pixels are a view of the received bytes, not a Python message's copy)."""
        try:
            image = image_from_cdr(data)
        except ImageEncodingError as exc:   # no header to answer with: logged
            self.get_logger().error(f'bad image: {exc}', throttle_duration_sec=1.0)
            return
        header = Header(frame_id=image.frame_id,
                        stamp=Time(sec=image.stamp_sec, nanosec=image.stamp_nanosec))
        self._track(image, header)

    def _track(self, image: SerializedImage, header: Header) -> None:
        """Track both hands in ``image`` (stamped ``header``); every hand gets a pose or a
        'no hand' status."""
        try:
            if (image.width, image.height) != (self.camera.width, self.camera.height):
                raise ImageEncodingError(
                    f'{CAMERA_REFUSAL_PREFIX}image {image.width}x{image.height}, calibrated '
                    f'{self.camera.width}x{self.camera.height}')
            rgb = image_to_rgb8(image, read_only=True)
            outcomes = self.pipeline.process(rgb, stamp_to_seconds(header.stamp))
        except Exception as exc:   # a frame must never stop the node
            if not isinstance(exc, ImageEncodingError):
                self.get_logger().error(f'two-hand tracking failed: {exc!r}\n'
                                        f'{traceback.format_exc()}', throttle_duration_sec=1.0)
            for h in HANDS:
                self.status[h].publish(String(data=f'no hand: {exc}'))
            return
        for h in HANDS:
            self._publish(outcomes[h], header)

    def _publish(self, outcome: HandOutcome, header: Header) -> None:
        hand = outcome.hand
        if isinstance(outcome.outcome, Tracked) and outcome.q is not None:
            wrist = self.poses[hand].publish(np.asarray(outcome.q), header)
            if self.tf_pub is not None:
                self.tf_pub.publish(wrist_pose_to_tf_msg(wrist,
                                                         child_frame_id=self.frames[hand]))
            how = (f'handedness evidence {outcome.evidence:+.2f}' if np.isfinite(outcome.evidence)
                   else 'handedness from continuity')
            self.status[hand].publish(String(data=f'tracking: {how}'))
        else:
            self.status[hand].publish(String(data=f'no hand: {outcome.outcome.reason}'))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``two_hands_node``."""
    return run_node(TwoHandsNode, args)


if __name__ == '__main__':
    sys.exit(main())
