"""The lean latency subscriber: per-window figures, and the probe process recording stamp and
arrival of every JointState over DDS."""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Time
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from colorglove_ros.ros.latency_probe import LatencyProbe, ProbeRecord, window_summaries
from colorglove_ros.ros.pipeline_run import ik_times_ms


def test_window_summaries_rate_and_percentiles() -> None:
    arrival = np.arange(0, 20_000_000_000, 100_000_000, dtype=np.int64)   # 10 Hz for 20 s
    latency = np.where(arrival < 10_000_000_000, 20_000_000, 50_000_000)  # 20 ms, then 50 ms
    rows = window_summaries(ProbeRecord(arrival - latency, arrival), 10.0)
    assert [r['joint_states'] for r in rows] == [100, 100]
    assert [r['rate_hz'] for r in rows] == [10.0, 10.0]
    assert rows[0]['latency_p95_ms'] == pytest.approx(20.0)
    assert rows[1]['latency_p50_ms'] == pytest.approx(50.0)
    assert ProbeRecord(arrival - latency, arrival).rate_hz == pytest.approx(10.0)


def test_ik_times_from_status_lines() -> None:
    statuses = ['tracking: 12 constraints (cam0 12), reprojection 2.1 px, IK 4.5 ms',
                'no hand: lost', 'tracking: 9 constraints (cam0 9), reprojection nan px, IK 11 ms']
    assert ik_times_ms(statuses) == [4.5, 11.0]


def _wait_for_subscribers(publishers: list, timeout_s: float = 10.0) -> None:
    """Wait until every publisher has a subscriber (the probe), or ``timeout_s`` has passed."""
    deadline = time.monotonic() + timeout_s
    while (min(p.get_subscription_count() for p in publishers) == 0
           and time.monotonic() < deadline):
        time.sleep(0.05)


def _probe_run(topics: tuple[str, ...], topic_of: list[int], stamp_of: Callable[[int], int]
               ) -> tuple[ProbeRecord, list[int]]:
    """Start a probe of ``topics``; publish JointState k on topic ``topic_of[k]``, stamped
    ``stamp_of(k)`` (ns, taken as it is sent); return what the probe recorded and the stamps
    sent."""
    probe = LatencyProbe(topics=topics)
    probe.start()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('probe_test', context=context)
        qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
        pubs = [node.create_publisher(JointState, topic, qos) for topic in topics]
        _wait_for_subscribers(pubs)
        sent = []
        for k, index in enumerate(topic_of):
            stamp = stamp_of(k)
            sent.append(stamp)
            sec, nanosec = divmod(stamp, 10**9)
            pubs[index].publish(JointState(header=Header(stamp=Time(sec=sec, nanosec=nanosec))))
            time.sleep(0.02)
        assert probe.wait_for_first(5.0)
        time.sleep(0.5)
    finally:
        record = probe.stop()
        rclpy.try_shutdown(context=context)
    return record, sent


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_probe_process_records_stamp_and_arrival() -> None:
    record, sent = _probe_run(('/hand/joint_states',), [0] * 20,
                              lambda _k: time.time_ns() - 30_000_000)   # taken 30 ms ago
    assert list(record.stamp_ns) == sent
    assert np.all(record.latencies_s >= 0.030) and np.all(record.latencies_s < 1.0)


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_close_ends_a_running_probe_cleanly() -> None:
    """close() (a run stopped before its record is read) stops the probe with SIGINT, as its
    own shutdown path expects, not SIGKILL, and removes its folder."""
    probe = LatencyProbe()
    probe.start()
    folder = probe.output.parent
    probe.close()
    assert probe.process.returncode == 0
    assert not folder.exists()


def test_record_of_one_topic() -> None:
    record = ProbeRecord(np.array([1, 2, 3, 4]), np.array([11, 12, 13, 14]), np.array([0, 1, 1, 0]))
    assert list(record.of_topic(1).stamp_ns) == [2, 3]
    assert list(record.of_topic(0).arrival_ns) == [11, 14]
    single = ProbeRecord(np.array([1, 2]), np.array([11, 12]))
    assert single.of_topic(0) is single and len(single.of_topic(1).stamp_ns) == 0


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_probe_records_which_topic_each_joint_state_came_on() -> None:
    """A probe of both hands' topics keeps their JointStates apart."""
    topic_of = [1, 0, 0, 1, 0, 0]                     # message k (stamped k s) goes on this topic
    record, _ = _probe_run(('/hand/right/joint_states', '/hand/left/joint_states'), topic_of,
                           lambda k: k * 10**9)
    assert sorted(record.of_topic(0).stamp_ns // 10**9) == [1, 2, 4, 5]
    assert sorted(record.of_topic(1).stamp_ns // 10**9) == [0, 3]


def test_stage_latencies_are_each_stage_topics_own() -> None:
    record = ProbeRecord(np.zeros(0, np.int64), np.zeros(0, np.int64),
                         stage_stamp_ns=np.array([0, 0, 10_000_000]),
                         stage_arrival_ns=np.array([5_000_000, 9_000_000, 12_000_000]),
                         stage_index=np.array([0, 1, 0]))
    np.testing.assert_allclose(record.stage_latencies_s(0), [0.005, 0.002])
    np.testing.assert_allclose(record.stage_latencies_s(1), [0.009])
    assert len(ProbeRecord(np.zeros(0), np.zeros(0)).stage_latencies_s(0)) == 0


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_probe_records_the_stage_topics_stamps_apart_from_the_joint_states() -> None:
    """With stage topics the probe takes their messages serialized and records each one's
    header stamp and arrival under its stage index; the JointStates stay on their own."""
    from colorglove_msgs.msg import HandObservation, HandPoseCandidates

    from colorglove_ros.ros.pipeline_run import STAGE_OUTPUTS

    probe = LatencyProbe(stage_topics=STAGE_OUTPUTS)
    probe.start()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('probe_stage_test', context=context)
        qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
        pubs = [node.create_publisher(kind, topic, qos) for kind, (topic, _) in
                zip((HandObservation, HandPoseCandidates), STAGE_OUTPUTS, strict=True)]
        joints = node.create_publisher(JointState, '/hand/joint_states', qos)
        _wait_for_subscribers([*pubs, joints])
        sent = []
        for k in range(6):
            stamp = time.time_ns() - 20_000_000          # taken 20 ms ago
            header = Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9))
            sent.append(stamp)
            observation = HandObservation(header=header, hand_found=True, status='x' * k)
            pubs[0].publish(observation)
            pubs[1].publish(HandPoseCandidates(header=header, observation=observation))
            joints.publish(JointState(header=header))
            time.sleep(0.02)
        assert probe.wait_for_first(5.0)
        time.sleep(0.5)
    finally:
        record = probe.stop()
        rclpy.try_shutdown(context=context)
    assert list(record.stamp_ns) == sent
    for index in (0, 1):
        keep = record.stage_index == index
        assert list(record.stage_stamp_ns[keep]) == sent
        latencies = record.stage_latencies_s(index)
        assert np.all(latencies >= 0.020) and np.all(latencies < 1.0)


@pytest.mark.dds
@pytest.mark.usefixtures('isolated_ros_domain')
def test_a_probe_that_ended_gives_a_probe_error_with_its_exit() -> None:
    """The CPU reading and stop() of a probe whose process was killed (reaped or not) raise
    ProbeError naming how it ended, not OSError or a missing record."""
    from colorglove_ros.ros.latency_probe import ProbeError

    probe = LatencyProbe()
    probe.start()
    assert probe.failure() == '' and probe.cpu_seconds() >= 0.0
    probe.process.kill()
    probe.process.wait()
    with pytest.raises(ProbeError, match='killed by signal 9 before the run ended'):
        probe.cpu_seconds()
    with pytest.raises(ProbeError, match='killed by signal 9'):
        probe.stop()
    assert not probe.output.parent.exists()
