"""Bag QoS as rosbag2 Jazzy handles it: the recorder matches what publishers offer (a
best-effort publisher is recorded), the player offers the recorded QoS again, publishes /clock
and loops."""
from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from colorglove_ros.ros.bag_qos import (
    publisher_qos_for_recorded,
    qos_from_recorded,
    subscription_qos_for_offers,
)
from colorglove_ros.ros.typestore import colorglove_typestore
from colorglove_ros.tools.play_bag import BagPlayer
from colorglove_ros.tools.record_bag import BagRecorder, offered_qos

RELIABLE = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
BEST_EFFORT = QoSProfile(depth=5, reliability=QoSReliabilityPolicy.BEST_EFFORT)
LATCHED = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)


def test_recorder_request_follows_the_offers() -> None:
    assert subscription_qos_for_offers([RELIABLE]).reliability == QoSReliabilityPolicy.RELIABLE
    mixed = subscription_qos_for_offers([RELIABLE, BEST_EFFORT])
    assert mixed.reliability == QoSReliabilityPolicy.BEST_EFFORT
    assert subscription_qos_for_offers([LATCHED]).durability == \
        QoSDurabilityPolicy.TRANSIENT_LOCAL
    assert subscription_qos_for_offers([LATCHED, RELIABLE]).durability == \
        QoSDurabilityPolicy.VOLATILE


def test_recorded_qos_round_trips_and_the_player_offers_it() -> None:
    deadline = QoSProfile(depth=3, reliability=QoSReliabilityPolicy.BEST_EFFORT,
                          deadline=Duration(seconds=0, nanoseconds=500_000_000))
    back = qos_from_recorded(offered_qos(deadline))
    assert back.reliability == QoSReliabilityPolicy.BEST_EFFORT
    assert back.deadline.nanoseconds == 500_000_000
    assert qos_from_recorded(offered_qos(LATCHED)).durability == \
        QoSDurabilityPolicy.TRANSIENT_LOCAL
    agreed = publisher_qos_for_recorded([offered_qos(BEST_EFFORT), offered_qos(BEST_EFFORT)])
    assert agreed.reliability == QoSReliabilityPolicy.BEST_EFFORT
    disagreed = publisher_qos_for_recorded([offered_qos(BEST_EFFORT), offered_qos(RELIABLE)])
    assert disagreed.reliability == QoSReliabilityPolicy.RELIABLE
    assert publisher_qos_for_recorded([]).reliability == QoSReliabilityPolicy.RELIABLE


def _bag_with_best_effort_topic(path: Path, count: int) -> None:
    store = colorglove_typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/test/joints', 'sensor_msgs/msg/JointState',
                                     typestore=store, offered_qos_profiles=[
                                         offered_qos(BEST_EFFORT)])
        for index in range(count):
            writer.write(conn, 5_000_000_000 + index * 10_000_000,
                         serialize_message(JointState(name=['a'], position=[float(index)])))


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_player_offers_recorded_qos_publishes_clock_and_recorder_keeps_best_effort(
        tmp_path: Path) -> None:
    _bag_with_best_effort_topic(tmp_path / 'in', 5)
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        player = BagPlayer(tmp_path / 'in', context=context)
        player.publish_clock()
        recorder = BagRecorder(tmp_path / 'out', ['/test/joints', '/test/reliable'],
                               context=context)
        probe = rclpy.create_node('probe', context=context)
        probe.create_publisher(JointState, '/test/reliable', RELIABLE)
        clocks: list[Clock] = []
        probe.create_subscription(Clock, '/clock', clocks.append, 10)
        for node in (player, recorder, probe):
            executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        info = probe.get_publishers_info_by_topic('/test/joints')
        assert [i.qos_profile.reliability for i in info] == [QoSReliabilityPolicy.BEST_EFFORT]
        deadline = time.monotonic() + 10.0
        while recorder.pending and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not recorder.pending, 'recorder never subscribed'
        requested = {s.topic_name: s.qos_profile.reliability for s in recorder.subscriptions}
        assert requested == {'/test/joints': QoSReliabilityPolicy.BEST_EFFORT,
                             '/test/reliable': QoSReliabilityPolicy.RELIABLE}
        time.sleep(0.5)
        for _ in range(2):                               # two passes, as --loop plays
            assert player.play(rate=0.0, pace_topic=None, pace_on=None,
                               pace_timeout_s=1.0) == 5
            time.sleep(0.3)
        deadline = time.monotonic() + 5.0
        while recorder.counts.get('/test/joints', 0) < 10 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert recorder.counts.get('/test/joints', 0) == 10
        assert len(clocks) >= 9 and clocks[0].clock.sec == 5
        executor.shutdown()
        spinner.join(timeout=5.0)
        recorder.close()
        player.close()
    finally:
        rclpy.try_shutdown(context=context)
    with AnyReader([tmp_path / 'out']) as reader:
        (conn,) = [c for c in reader.connections if c.topic == '/test/joints']
        assert len(list(reader.messages(connections=[conn]))) == 10
        assert conn.ext.offered_qos_profiles[0].reliability.name == 'BEST_EFFORT'
