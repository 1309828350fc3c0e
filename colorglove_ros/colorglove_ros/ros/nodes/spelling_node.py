"""spelling_node: finger-spelled letters from ``hand/joint_states`` + ``hand/wrist_pose`` (the
orientation tells G/H/P/Q apart), each committed letter as ``std_msgs/String`` on
``hand/spelled_letters`` and the text so far on ``hand/spelled_text``. With an
``image_classifier_file`` (``core/hand/observation_features.py``) it also subscribes to
``hand/observation`` (segmentation_node's ``colorglove_msgs/HandObservation``: the tiny label
image, the crop and the blobs) and gives each pose the observation of its own stamp; a pose
whose observation has not come is read from the pose alone."""
from __future__ import annotations

import sys
from collections import OrderedDict

import numpy as np
from colorglove_msgs.msg import HandObservation
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_msgs.msg import String

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.observation_features import OBSERVATION_FEATURES, frame_features
from colorglove_ros.core.hand.pose_classifier import load_pose_classifier
from colorglove_ros.core.hand.spelling import (
    DEFAULT_LETTER_CLASSIFIER,
    DEFAULT_LETTER_IMAGE_CLASSIFIER,
    LETTER_FEATURES,
    Speller,
    SpellingConfig,
    SpellingError,
)
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import (
    blobs_from_observation_msg,
    crop_from_observation_msg,
    stamp_key,
    stamp_to_seconds,
    tiny_labels_from_observation_msg,
)
from colorglove_ros.ros.nodes.common import (
    OBSERVATION_TOPIC,
    TRACKING_STATUS_TOPIC,
    declare,
    declare_classifier,
    declare_frame_prefix,
    hand_model_from_calibration,
    run_node,
    startup_errors,
    subscribe_tracked_pose,
)
from colorglove_ros.ros.pose_pairing import is_no_hand_status

__all__ = ['SpellingNode', 'main']

_KEPT_OBSERVATIONS = 30     # observations waiting for their pose (about a second at 30 Hz)


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
        image_path = declare(self, 'image_classifier_file', DEFAULT_LETTER_IMAGE_CLASSIFIER,
                             'letter classifier of the image evidence (colorglove_train_hand_'
                             'classifiers --what letter_images); "" reads the pose alone')
        image_weight = declare(self, 'image_weight', SpellingConfig().image_weight,
                               "the image classifier's weight", 0.0, 100.0)
        image = None
        if image_path:
            with startup_errors('spelling_node'):
                image = load_pose_classifier(resolve_path(image_path), OBSERVATION_FEATURES)
        with startup_errors('spelling_node'):
            config = SpellingConfig(image_weight=float(image_weight))
        self.speller = Speller(config, model, classifier, image)
        # observation features by stamp, waiting for their pose (oldest dropped first)
        self.observations: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()
        if image is not None:
            self.create_subscription(HandObservation, OBSERVATION_TOPIC, self.on_observation,
                                     10)
        self.text = ''
        self.letter_pub = self.create_publisher(String, 'hand/spelled_letters', 10)
        self.text_pub = self.create_publisher(String, 'hand/spelled_text', 10)
        subscribe_tracked_pose(self, self.on_pose, frame_prefix)
        self.create_subscription(String, TRACKING_STATUS_TOPIC, self.on_status, 10)

    def on_observation(self, msg: HandObservation) -> None:
        """Keep a found hand's observation features until the pose of its stamp comes."""
        if not msg.hand_found or not len(msg.tiny_labels):
            return
        try:
            features = frame_features(tiny_labels_from_observation_msg(msg),
                                      crop_from_observation_msg(msg),
                                      blobs_from_observation_msg(msg))
        except (ColorGloveError, ValueError) as exc:
            self.get_logger().warn(f'bad observation: {exc}', throttle_duration_sec=1.0)
            return
        self.observations[stamp_key(msg.header.stamp)] = features
        while len(self.observations) > _KEPT_OBSERVATIONS:
            self.observations.popitem(last=False)

    def on_pose(self, q: np.ndarray, wrist: PoseStamped) -> None:
        """Feed a complete frame (with its observation, when an image classifier reads it)
        to the speller; publish a committed letter."""
        stamp = wrist.header.stamp
        observation = self.observations.pop(stamp_key(stamp), None)
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
