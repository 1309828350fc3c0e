"""TrackerOutputs builds the skeleton markers, and the wrist pose when its caller does not need
it, only while something subscribes to them."""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

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


@contextmanager
def _outputs(monkeypatch: pytest.MonkeyPatch, builder: str,
             record: Callable[..., object]) -> Iterator[tuple[Node, TrackerOutputs]]:
    """A node of its own context and its TrackerOutputs, with ``common.<builder>`` calling
    ``record`` with its arguments before building."""
    real = getattr(common, builder)

    def counting(*args):
        record(*args)
        return real(*args)

    monkeypatch.setattr(common, builder, counting)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node('outputs_test', context=context)
        yield node, TrackerOutputs(node)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def _subscribe(node: Node, message_type: type, topic: str, publisher) -> None:
    """Subscribe on ``node`` and wait until ``publisher`` sees the subscriber."""
    node.create_subscription(message_type, topic, lambda msg: None, 10)
    deadline = time.monotonic() + 10.0
    while not publisher.get_subscription_count() and time.monotonic() < deadline:
        time.sleep(0.05)


def test_markers_are_built_only_for_a_subscriber(monkeypatch: pytest.MonkeyPatch) -> None:
    built = []
    with _outputs(monkeypatch, 'skeleton_to_markers_msg',
                  lambda keypoints, header: built.append(keypoints is None)) as (node, outputs):
        q, keypoints = np.zeros(26), np.zeros((21, 3))
        outputs.publish_pose(q, keypoints, Header())
        outputs.publish_no_hand(Header(), 'lost')
        assert built == []                      # nobody listens: nothing built
        _subscribe(node, MarkerArray, MARKERS_TOPIC, outputs.markers)
        outputs.publish_pose(q, keypoints, Header())
        outputs.publish_no_hand(Header(), 'lost')
        assert built == [False, True]           # the skeleton, then its clearing


def test_wrist_pose_is_built_only_when_wanted_or_subscribed(monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    built = []
    with _outputs(monkeypatch, 'pose_to_wrist_pose_msg',
                  lambda q, header: built.append(True)) as (node, outputs):
        q, keypoints = np.zeros(26), np.zeros((21, 3))
        q[2] = 0.5
        assert outputs.publish_pose(q, keypoints, Header(), wrist_wanted=False) is None
        assert built == []                      # nobody listens and the caller needs none
        wrist = outputs.publish_pose(q, keypoints, Header())
        assert built == [True] and wrist.pose.position.z == 0.5   # wanted by default
        _subscribe(node, PoseStamped, WRIST_POSE_TOPIC, outputs.pose.wrist)
        wrist = outputs.publish_pose(q, keypoints, Header(), wrist_wanted=False)
        assert built == [True, True] and wrist is not None        # a subscriber gets it
