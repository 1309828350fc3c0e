"""TrackerOutputs builds the skeleton markers, and the wrist pose when its caller does not need
it, only while something subscribes to them."""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from colorglove_ros.ros.nodes import common
from colorglove_ros.ros.nodes.common import MARKERS_TOPIC, WRIST_POSE_TOPIC, TrackerOutputs

pytestmark = [pytest.mark.dds, pytest.mark.usefixtures('isolated_ros_domain')]


def test_markers_are_built_only_for_a_subscriber(monkeypatch: pytest.MonkeyPatch) -> None:
    built = []
    real = common.skeleton_to_markers_msg

    def counting(keypoints, header):
        built.append(keypoints is None)
        return real(keypoints, header)

    monkeypatch.setattr(common, 'skeleton_to_markers_msg', counting)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node('outputs_test', context=context)
        outputs = TrackerOutputs(node)
        q, keypoints = np.zeros(26), np.zeros((21, 3))
        outputs.publish_pose(q, keypoints, Header())
        outputs.publish_no_hand(Header(), 'lost')
        assert built == []                      # nobody listens: nothing built
        node.create_subscription(MarkerArray, MARKERS_TOPIC, lambda msg: None, 10)
        deadline = time.monotonic() + 10.0
        while not outputs.markers.get_subscription_count() and time.monotonic() < deadline:
            time.sleep(0.05)
        outputs.publish_pose(q, keypoints, Header())
        outputs.publish_no_hand(Header(), 'lost')
        assert built == [False, True]           # the skeleton, then its clearing
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_wrist_pose_is_built_only_when_wanted_or_subscribed(monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    built = []
    real = common.pose_to_wrist_pose_msg

    def counting(q, header):
        built.append(True)
        return real(q, header)

    monkeypatch.setattr(common, 'pose_to_wrist_pose_msg', counting)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node('wrist_outputs_test', context=context)
        outputs = TrackerOutputs(node)
        q, keypoints = np.zeros(26), np.zeros((21, 3))
        q[2] = 0.5
        assert outputs.publish_pose(q, keypoints, Header(), wrist_wanted=False) is None
        assert built == []                      # nobody listens and the caller needs none
        wrist = outputs.publish_pose(q, keypoints, Header())
        assert built == [True] and wrist.pose.position.z == 0.5   # wanted by default
        node.create_subscription(PoseStamped, WRIST_POSE_TOPIC, lambda msg: None, 10)
        deadline = time.monotonic() + 10.0
        while not outputs.pose.wrist.get_subscription_count() and time.monotonic() < deadline:
            time.sleep(0.05)
        wrist = outputs.publish_pose(q, keypoints, Header(), wrist_wanted=False)
        assert built == [True, True] and wrist is not None        # a subscriber gets it
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
