"""A node's ``DiagnosticArray`` on ``/diagnostics`` once a period, from its
:class:`~colorglove_ros.ros.diagnostics.FrameStats` (the node shell's half of
``ros.diagnostics``)."""
from __future__ import annotations

from collections.abc import Callable

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import Header

from colorglove_ros.ros.diagnostics import (
    DIAGNOSTICS_PERIOD_S,
    DIAGNOSTICS_TOPIC,
    FrameStats,
    diagnostic_array,
    status_msg,
)

__all__ = ['DiagnosticsPublisher']


class DiagnosticsPublisher:
    """Publishes ``stats`` as status ``'<node name>: <what>'`` of ``hardware_id`` every
    :data:`DIAGNOSTICS_PERIOD_S` (``hardware_id`` may be a function, read at each report)."""

    def __init__(self, node: Node, what: str, hardware_id: str | Callable[[], str],
                 stats: FrameStats) -> None:
        self.node = node
        self.name = f'{node.get_name()}: {what}'
        self.hardware_id = hardware_id
        self.stats = stats
        self.publisher = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        self._clock = node.get_clock()
        self._last_report = self._clock.now()
        self.timer = node.create_timer(DIAGNOSTICS_PERIOD_S, self.publish)

    def latency_s(self, stamp: Time) -> float:
        """Seconds from a frame's header ``stamp`` to now (the node's clock)."""
        # integer nanoseconds, as (now - Time.from_msg(stamp)) gives them, without the two
        # Time objects
        return (self._clock.now().nanoseconds - (stamp.sec * 1_000_000_000 + stamp.nanosec)
                ) * 1e-9

    def publish(self) -> None:
        """Publish the report of the period that ends now."""
        now = self.node.get_clock().now()
        period_s = (now - self._last_report).nanoseconds * 1e-9
        self._last_report = now
        hardware_id = self.hardware_id() if callable(self.hardware_id) else self.hardware_id
        status = status_msg(self.stats.summary(period_s), self.name, hardware_id)
        self.publisher.publish(diagnostic_array(Header(stamp=now.to_msg()), [status]))
