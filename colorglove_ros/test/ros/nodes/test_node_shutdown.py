"""A node ends quietly when ROS shuts down under it: once rclpy's SIGINT / SIGTERM handler has
shut the context down, the executor's next wait set and a callback's next publish raise
``RCLError`` ("context is not valid"); that is the end of the spin, not a crash with a
traceback. The same error while the context is valid still propagates."""
from __future__ import annotations

import pytest
import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException

from colorglove_ros.ros.nodes.common import ending_on_shutdown


def test_rcl_error_after_shutdown_ends_the_spin_quietly() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(RCLError), ending_on_shutdown(context):
            raise RCLError('failed to publish: unrelated failure while running')
        rclpy.shutdown(context=context)
        with ending_on_shutdown(context):
            raise RCLError("failed to initialize wait set: the given context is not valid")
        for interrupt in (KeyboardInterrupt, ExternalShutdownException):
            with ending_on_shutdown(context):
                raise interrupt()
    finally:
        rclpy.try_shutdown(context=context)


def test_other_errors_propagate() -> None:
    with pytest.raises(ValueError), ending_on_shutdown():
        raise ValueError('a bug in a callback')
