"""Record ROS topics (the tracker's outputs by default) into a rosbag2 (MCAP) with rosbags,
playable by ``ros2 bag play`` on a native install."""
from __future__ import annotations

import signal
import sys
import threading
import time
from pathlib import Path

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer

from colorglove_ros.ros.bag_qos import subscription_qos_for_offers
from colorglove_ros.ros.typestore import colorglove_typestore, message_class
from colorglove_ros.tools._cli import tool_parser

__all__ = ['DEFAULT_TOPICS', 'BagRecorder', 'main', 'offered_qos']

DEFAULT_TOPICS = ('/hand/joint_states', '/hand/wrist_pose', '/hand/markers',
                  '/hand/pose_candidates', '/hand/observation', '/tf', '/tf_static')


def _time(duration: Duration) -> QosTime:
    sec, nsec = divmod(duration.nanoseconds, 10**9)
    return QosTime(sec, nsec)


def offered_qos(profile: QoSProfile) -> Qos:
    """A publisher's offered QoS as rosbags writes it into rosbag2 metadata (as ``ros2 bag
    record`` does: discovery reports no history, so it is ``unknown`` with depth 0)."""
    return Qos(QosHistory(int(profile.history)), int(profile.depth),
               QosReliability(int(profile.reliability)), QosDurability(int(profile.durability)),
               _time(profile.deadline), _time(profile.lifespan),
               QosLiveliness(int(profile.liveliness)),
               _time(profile.liveliness_lease_duration),
               bool(profile.avoid_ros_namespace_conventions))


class BagRecorder(Node):
    """Subscribes to topics as raw CDR and writes every message to an MCAP bag."""

    def __init__(self, output: Path, topics: list[str], **kwargs) -> None:
        super().__init__('bag_recorder', **kwargs)
        self.typestore = colorglove_typestore()
        self.writer = Writer(output, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.lock = threading.Lock()
        self.pending = set(topics)
        self.connections = {}
        self.counts: dict[str, int] = {}
        self.create_timer(0.2, self.discover)

    def discover(self) -> None:
        """Subscribe to requested topics as soon as they appear in the graph (nothing once the
        context is shut down: Ctrl-C's handler may do that while a spin runs this timer)."""
        try:
            graph = self.get_topic_names_and_types()
        except Exception:
            if self.context.ok():
                raise
            return
        for topic, types in graph:
            if topic not in self.pending or not types:
                continue
            msgtype = types[0]
            publishers = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
            offered = [offered_qos(profile) for profile in publishers]
            with self.lock:
                self.connections[topic] = self.writer.add_connection(
                    topic, msgtype, typestore=self.typestore, offered_qos_profiles=offered)
            msg_class = message_class(msgtype)
            qos = subscription_qos_for_offers(publishers)
            self.create_subscription(msg_class, topic,
                                     lambda data, t=topic: self.write(t, data), qos, raw=True)
            self.pending.discard(topic)          # only once subscribed: others poll it
            self.get_logger().info(f'recording {topic} [{msgtype}] '
                                   f'({qos.reliability.name.lower()})')

    def write(self, topic: str, data: bytes) -> None:
        """Write one serialized message with the receive time."""
        with self.lock:
            self.writer.write(self.connections[topic], time.time_ns(), data)
            self.counts[topic] = self.counts.get(topic, 0) + 1

    def close(self) -> None:
        """Finish the bag file."""
        with self.lock:
            self.writer.close()


def main(argv: list[str] | None = None) -> int:
    """``colorglove_record_bag OUTPUT [--topics ...] [--duration S]``."""
    parser = tool_parser(__doc__.splitlines()[0], json_help=None)
    parser.add_argument('output', type=Path, help='bag folder to create (must not exist)')
    parser.add_argument('--topics', nargs='*', default=list(DEFAULT_TOPICS))
    parser.add_argument('--duration', type=float, default=0.0, help='seconds (0 = until Ctrl-C)')
    args, ros_args = parser.parse_known_args(argv)
    if args.output.exists():
        print(f'colorglove_record_bag: {args.output} exists already', file=sys.stderr)
        return 2
    rclpy.init(args=ros_args)
    recorder = BagRecorder(args.output, args.topics)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    deadline = time.monotonic() + args.duration if args.duration > 0 else float('inf')
    try:
        while not stop.is_set() and time.monotonic() < deadline and rclpy.ok():
            rclpy.spin_once(recorder, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass   # Ctrl-C: rclpy's own handler may have shut the context down mid-spin
    finally:
        recorder.close()
        for topic, count in sorted(recorder.counts.items()):
            print(f'{topic}: {count} messages', flush=True)
        recorder.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
