"""Separate-process publisher for the DDS round-trip test: publishes sample messages."""
from __future__ import annotations

import sys
import time

import rclpy
from message_samples import SAMPLES
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy


def main() -> int:
    kind, topic, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    msg_type, build = SAMPLES[kind]
    rclpy.init()
    node = rclpy.create_node('dds_test_publisher')
    qos = QoSProfile(depth=50, reliability=QoSReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.VOLATILE)
    publisher = node.create_publisher(msg_type, topic, qos)
    try:
        deadline = time.monotonic() + seconds
        seq = 0
        while time.monotonic() < deadline:
            if publisher.get_subscription_count() > 0:
                publisher.publish(build(seq))
                seq += 1
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
