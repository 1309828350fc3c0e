"""Each custom message crosses DDS intact between two separate processes."""
from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from message_samples import SAMPLES
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from repo_paths import TEST_DIR

pytestmark = pytest.mark.dds


def _assert_messages_equal(received, expected) -> None:
    for field in expected.get_fields_and_field_types():
        got, want = getattr(received, field), getattr(expected, field)
        if hasattr(want, 'get_fields_and_field_types'):
            _assert_messages_equal(got, want)
        elif isinstance(want, list) and want and hasattr(want[0], 'get_fields_and_field_types'):
            assert len(got) == len(want), field
            for g, w in zip(got, want, strict=True):
                _assert_messages_equal(g, w)
        else:
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want), err_msg=field)


@pytest.mark.parametrize('kind', sorted(SAMPLES))
def test_custom_message_crosses_processes(kind: str, isolated_ros_domain: dict) -> None:
    msg_type, build = SAMPLES[kind]
    topic = f'/test/{kind}'
    publisher = subprocess.Popen(
        [sys.executable, str(TEST_DIR / 'dds_publisher.py'), kind, topic, '20'],
        env=isolated_ros_domain, cwd=TEST_DIR)
    received = []
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('dds_test_subscriber', context=context)
    try:
        node.create_subscription(msg_type, topic, received.append,
                                 QoSProfile(depth=50, reliability=QoSReliabilityPolicy.RELIABLE))
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 20
        while len(received) < 5 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        publisher.terminate()
        publisher.wait(timeout=10)
    assert len(received) >= 5, f'only {len(received)} {kind} messages arrived'
    for msg in received:
        seq = msg.header.stamp.sec - 1000
        _assert_messages_equal(msg, build(seq))
