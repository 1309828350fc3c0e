"""Helpers shared by the node shells: parameter declaration and the Jazzy ``main`` pattern."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
)
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.ros.shm_cleanup import clean_stale_fastdds_segments

__all__ = ['LATEST_ONLY', 'LATEST_IMAGE', 'declare', 'run_node']

# Between pipeline stages keep only the newest message: a slow stage drops old frames instead
# of queueing them without bound.
LATEST_ONLY = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                         reliability=QoSReliabilityPolicy.RELIABLE)
# Camera images: sensor-data style (best effort matches reliable and best-effort publishers),
# newest frame only: whatever the offered rate, segmentation works on the latest frame and
# drops older ones, so latency stays bounded by the processing time plus a frame period.
LATEST_IMAGE = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                          reliability=QoSReliabilityPolicy.BEST_EFFORT)


def declare(node: Node, name: str, default: Any, description: str,
            minimum: float | None = None, maximum: float | None = None, *,
            read_only: bool = True) -> Any:
    """Declare a parameter with a description (and a range for numbers); return its value.

    Parameters are read at start-up unless ``read_only=False``: ROS then refuses a run-time
    change of a read-only one with its standard reason, so nobody believes it took effect.
    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    if minimum is not None and maximum is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(minimum),
                                                     to_value=int(maximum), step=0)]
        elif isinstance(default, float):
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(minimum), to_value=float(maximum), step=0.0)]
    return node.declare_parameter(name, default, descriptor).value


def run_node(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init rclpy, spin the node made by ``factory`` until shutdown, and clean up (Jazzy style).

    A node that cannot start (bad configuration) logs the reason and exits with code 1.
    Shared-memory segments of killed Fast DDS participants are removed first (a respawned
    node must not pile them up).
    """
    clean_stale_fastdds_segments()
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        print(f'[FATAL] {exc}', flush=True)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


class StartupError(ColorGloveError):
    """A node cannot start: missing device, file, database or bad configuration."""


__all__ += ['StartupError']
