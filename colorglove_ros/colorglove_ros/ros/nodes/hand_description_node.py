"""hand_description_node: the URDF of the calibrated hand (``hand_length_m`` and
``finger_length_factors`` of the calibration file, link and joint names with ``frame_prefix``)
on ``robot_description`` (``std_msgs/String``, latched: reliable, transient local, depth 1, as
robot_state_publisher publishes it), and as its read-only parameter ``robot_description``.

It is for graphs without robot_state_publisher (pip-only machines, or the native launch file
with ``use_robot_state_publisher:=false``): there robot_state_publisher, given the same URDF by
the launch file, publishes ``robot_description`` and the finger TF itself.
"""
from __future__ import annotations

import sys

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import String

from colorglove_ros.core.hand.urdf import calibrated_hand_urdf
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.nodes.common import (
    declare_calibration_file,
    declare_frame_prefix,
    declare_hand,
    run_node,
    startup_errors,
)

__all__ = ['ROBOT_DESCRIPTION_TOPIC', 'ROBOT_DESCRIPTION_QOS', 'HandDescriptionNode', 'main']

EXECUTABLE = 'hand_description_node'
ROBOT_DESCRIPTION_TOPIC = 'robot_description'
"""Topic (and parameter) of the URDF, as robot_state_publisher names it."""
ROBOT_DESCRIPTION_QOS = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                                   reliability=QoSReliabilityPolicy.RELIABLE,
                                   durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
"""robot_state_publisher's ``rclcpp::QoS(1).transient_local()``: a late subscriber (RViz,
Foxglove) asking for transient local still gets the description."""


class HandDescriptionNode(Node):
    """Publishes the calibrated hand's URDF once, latched."""

    def __init__(self, **kwargs) -> None:
        super().__init__('hand_description', **kwargs)
        calibration_file = declare_calibration_file(
            self, 'calibration YAML whose hand_length_m and finger_length_factors size the URDF')
        frame_prefix = declare_frame_prefix(self, EXECUTABLE)
        hand = declare_hand(self, EXECUTABLE)
        with startup_errors(EXECUTABLE, ValueError):
            self.urdf = calibrated_hand_urdf(resolve_path(calibration_file), frame_prefix, hand)
        # the generated URDF, never a value given from outside (a params file's '/**' section
        # meant for robot_state_publisher must not replace it)
        self.declare_parameter(
            ROBOT_DESCRIPTION_TOPIC, self.urdf,
            ParameterDescriptor(description='URDF of the calibrated hand (generated from '
                                            'calibration_file and frame_prefix)',
                                read_only=True),
            ignore_override=True)
        self.publisher = self.create_publisher(String, ROBOT_DESCRIPTION_TOPIC,
                                               ROBOT_DESCRIPTION_QOS)
        self.publisher.publish(String(data=self.urdf))
        self.get_logger().info(f'published the hand URDF ({calibration_file}, frame prefix '
                               f'{frame_prefix!r}) on {self.publisher.topic_name}')


def main(args: list[str] | None = None) -> int:
    """Entry point of ``hand_description_node``."""
    return run_node(HandDescriptionNode, args)


if __name__ == '__main__':
    sys.exit(main())
