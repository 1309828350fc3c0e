"""TrackerOutputs builds the skeleton markers only while something subscribes to them."""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from colorglove_ros.ros.nodes import common
from colorglove_ros.ros.nodes.common import MARKERS_TOPIC, TrackerOutputs

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
