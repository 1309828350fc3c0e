"""spelling_node: finger-spelled letters from ``hand/joint_states`` + ``hand/wrist_pose`` (the
orientation tells G/H/P/Q apart), each committed letter as ``std_msgs/String`` on
``hand/spelled_letters`` and the text so far on ``hand/spelled_text``."""
from __future__ import annotations

import sys

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from colorglove_ros.core.camera import CalibrationError, load_calibration
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.spelling import Speller, SpellingError
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.conversions import stamp_to_seconds
from colorglove_ros.ros.nodes.common import (
    StartupError,
    declare,
    run_node,
)
from colorglove_ros.ros.pose_pairing import PosePairer, is_no_hand_status

__all__ = ['SpellingNode', 'main']


class SpellingNode(Node):
    """Hold-to-commit finger-spelling of the tracked hand."""

    def __init__(self, **kwargs) -> None:
        super().__init__('spelling', **kwargs)
        calibration_file = declare(self, 'calibration_file', 'config/calibration.yaml',
                                   'camera calibration YAML (for the hand length)')
        self.max_text = declare(self, 'max_text_length', 200,
                                'longest text kept on hand/spelled_text (oldest letters dropped)',
                                1, 100000)
        try:
            model = HandModel(load_calibration(resolve_path(calibration_file)).hand_length_m)
        except (CalibrationError, ValueError) as exc:
            raise StartupError(f'spelling_node cannot start: {exc}') from exc
        self.speller = Speller(model=model)
        self.pairer = PosePairer()
        self.text = ''
        self.letter_pub = self.create_publisher(String, 'hand/spelled_letters', 10)
        self.text_pub = self.create_publisher(String, 'hand/spelled_text', 10)
        self.create_subscription(JointState, 'hand/joint_states',
                                 lambda m: self.on_pose(self.pairer.add_joints(m)), 10)
        self.create_subscription(PoseStamped, 'hand/wrist_pose',
                                 lambda m: self.on_pose(self.pairer.add_wrist(m)), 10)
        self.create_subscription(String, 'hand/tracking_status', self.on_status, 10)

    def on_pose(self, paired: tuple[np.ndarray, PoseStamped] | None) -> None:
        """Feed a complete frame to the speller; publish a committed letter."""
        if paired is None:
            return
        q, wrist = paired
        try:
            letter = self.speller.update(q, stamp_to_seconds(wrist.header.stamp))
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
