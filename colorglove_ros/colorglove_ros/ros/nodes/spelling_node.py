"""spelling_node: finger-spelled letters from ``hand/joint_states`` + ``hand/wrist_pose`` (the
orientation tells G/H/P/Q apart), each committed letter as ``std_msgs/String`` on
``hand/spelled_letters`` and the text so far on ``hand/spelled_text``. With an
``image_classifier_file`` (``core/hand/observation_features.py``) it also subscribes to
``hand/observation`` (segmentation_node's ``colorglove_msgs/HandObservation``: the tiny label
image, the crop and the blobs) and gives each pose the observation of its own stamp; a pose
whose observation has not come is read from the pose alone."""
from __future__ import annotations

import sys

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_msgs.msg import String

from colorglove_ros.core.hand.spelling import (
    DEFAULT_LETTER_CLASSIFIER,
    DEFAULT_LETTER_IMAGE_CLASSIFIER,
    LETTER_FEATURES,
    Speller,
    SpellingConfig,
    SpellingError,
)
from colorglove_ros.ros.conversions import stamp_to_seconds
from colorglove_ros.ros.nodes.common import (
    TRACKING_STATUS_TOPIC,
    ObservationFeatures,
    declare,
    declare_classifier,
    declare_frame_prefix,
    declare_image_classifier,
    hand_model_from_calibration,
    run_node,
    startup_errors,
    subscribe_tracked_pose,
)
from colorglove_ros.ros.pose_pairing import is_no_hand_status

__all__ = ['SpellingNode', 'main']


class SpellingNode(Node):
    """Hold-to-commit finger-spelling of the tracked hand."""

    def __init__(self, **kwargs) -> None:
        super().__init__('spelling', **kwargs)
        model = hand_model_from_calibration(self, 'spelling_node')
        self.max_text = declare(self, 'max_text_length', 200,
                                'longest text kept on hand/spelled_text (oldest letters dropped)',
                                1, 100000)
        frame_prefix = declare_frame_prefix(self, 'spelling_node')
        classifier = declare_classifier(self, 'spelling_node', DEFAULT_LETTER_CLASSIFIER,
                                        LETTER_FEATURES, 'letter templates')
        image, image_weight = declare_image_classifier(
            self, 'spelling_node', DEFAULT_LETTER_IMAGE_CLASSIFIER,
            'colorglove_train_hand_classifiers --what letter_images',
            SpellingConfig().image_weight)
        with startup_errors('spelling_node'):
            config = SpellingConfig(image_weight=image_weight)
        self.speller = Speller(config, model, classifier, image)
        self.observations = ObservationFeatures(self) if image is not None else None
        self.text = ''
        self.letter_pub = self.create_publisher(String, 'hand/spelled_letters', 10)
        self.text_pub = self.create_publisher(String, 'hand/spelled_text', 10)
        subscribe_tracked_pose(self, self.on_pose, frame_prefix)
        self.create_subscription(String, TRACKING_STATUS_TOPIC, self.on_status, 10)

    def on_pose(self, q: np.ndarray, wrist: PoseStamped) -> None:
        """Feed a complete frame (with its observation, when an image classifier reads it)
        to the speller; publish a committed letter."""
        stamp = wrist.header.stamp
        observation = None if self.observations is None else self.observations.pop(stamp)
        try:
            letter = self.speller.update(q, stamp_to_seconds(stamp), observation)
        except SpellingError as exc:
            self.get_logger().warn(f'bad pose: {exc}', throttle_duration_sec=1.0)
            return
        if letter is None:
            return
        self.text = (self.text + letter)[-self.max_text:]
        self.letter_pub.publish(String(data=letter))
        self.text_pub.publish(String(data=self.text))

    def on_status(self, msg: String) -> None:
        """A lost hand ends the current hold."""
        if is_no_hand_status(msg.data):
            self.speller.update(None, 0.0)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``spelling_node``."""
    return run_node(SpellingNode, args)


if __name__ == '__main__':
    sys.exit(main())
