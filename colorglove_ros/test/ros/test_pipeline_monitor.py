"""The benchmark's monitor (``pipeline_run.PipelineMonitor``) learns which frames were offered
from each frame's CameraInfo, not from the 1 MB image, and ignores CameraInfo stamped before
it started (a bag's first one, primed as recorded); the bag feed waits for every CameraInfo
reader, the monitor's too."""
from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
import rclpy
from builtin_interfaces.msg import Time
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from colorglove_ros.ros.lean_executor import LeanExecutor
from colorglove_ros.ros.pipeline_run import (
    CAMERA_INFO_SUBSCRIBERS,
    IMAGE_SUBSCRIBERS,
    PipelineMonitor,
    bag_feed,
)

_RELIABLE = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=10,
                       reliability=QoSReliabilityPolicy.RELIABLE)


@pytest.fixture
def context(ros_context: rclpy.Context) -> rclpy.Context:
    """The test's own rclpy context (``ros_context``, test/conftest.py)."""
    return ros_context


def _wait(condition, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    return condition()


def test_monitor_counts_frames_from_camera_info(context: rclpy.Context) -> None:
    """Three CameraInfo stamped now are three frames; a CameraInfo stamped before the monitor
    started is not one, and an image (of a frame without CameraInfo) is not looked at."""
    monitor = PipelineMonitor(context=context)
    camera = rclpy.create_node('fake_camera', context=context)
    info_pub = camera.create_publisher(CameraInfo, '/camera/camera_info', _RELIABLE)
    image_pub = camera.create_publisher(Image, '/camera/image_raw', _RELIABLE)
    executor = LeanExecutor(context=context)
    executor.add_node(monitor)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        assert _wait(lambda: info_pub.get_subscription_count() == 1)
        assert image_pub.get_subscription_count() == 0      # it takes no image
        now_ns = time.time_ns()
        stamps = [divmod(now_ns + k * 33_000_000, 10**9) for k in range(3)]
        old = Header(stamp=Time(sec=1_600_000_000, nanosec=5))
        info_pub.publish(CameraInfo(header=old))
        for sec, nanosec in stamps:
            info_pub.publish(CameraInfo(header=Header(stamp=Time(sec=sec, nanosec=nanosec))))
        sec, nanosec = divmod(now_ns + 10**9, 10**9)
        image_pub.publish(Image(header=Header(stamp=Time(sec=sec, nanosec=nanosec))))
        assert _wait(lambda: len(monitor.frame_times) >= 3)
        time.sleep(0.3)                                      # anything more would come now
        with monitor.lock:
            seen = sorted(monitor.frame_times)
    finally:
        executor.shutdown()
        spinner.join(timeout=5.0)
        camera.destroy_node()
        monitor.destroy_node()
    assert seen == [tuple(stamp) for stamp in stamps]


def test_bag_feed_waits_for_every_camera_info_reader(tmp_path: Path) -> None:
    """The player waits for the image's reader (segmentation_node), for the CameraInfo's four
    (segmentation, lookup, IK and the monitor, which counts frames by it) and for what a
    second camera's topics need."""
    feed = bag_feed(tmp_path, waits={'/cam1/camera/image_raw': 1,
                                     '/cam1/camera/camera_info': 2})
    command = feed.command

    def value(option: str) -> str:
        return command[command.index(option) + 1]

    assert (IMAGE_SUBSCRIBERS, CAMERA_INFO_SUBSCRIBERS) == (1, 4)
    assert value('--min-subscribers') == '1' and value('--min-info-subscribers') == '4'
    at = command.index('--wait-for')
    assert command[at + 1:at + 3] == ['/cam1/camera/image_raw=1', '/cam1/camera/camera_info=2']
    assert '--wait-for' not in bag_feed(tmp_path).command
