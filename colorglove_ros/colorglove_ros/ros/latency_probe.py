"""A lean latency subscriber: a process that only subscribes to ``/hand/joint_states`` (or
the JointState topics it is given, e.g. both hands') and records, per JointState, its header
stamp and its arrival time (system clock). The camera node
and the bag player stamp frames at publish time with the system clock, so arrival minus stamp
is the camera-frame-to-JointState latency, free of the queueing a busy monitor adds (one that
also deserialises every camera image).

``python -m colorglove_ros.ros.latency_probe --output FILE [--topics T ...]`` runs it until
SIGINT/SIGTERM (or ``--duration``) and writes ``{"stamp_ns": [...], "arrival_ns": [...],
"topic_index": [...]}``; :class:`LatencyProbe` starts and stops such a process and reads what
it recorded. With ``--stage-topics TOPIC=TYPE ...`` it also records the stamp and arrival of
the messages of other topics whose messages start with a ``std_msgs/Header`` (e.g. the
pipeline's observation and candidates: where a frame's latency goes stage by stage), taken
serialized and only their stamp read, apart from the JointStates."""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from colorglove_ros import signal_exit
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.topic_arguments import topic_argument

__all__ = ['ProbeError', 'ProbeRecord', 'LatencyProbe', 'window_summaries', 'main']

JOINT_STATES_TOPIC = '/hand/joint_states'


@dataclass(frozen=True)
class ProbeRecord:
    """What the probe saw: header stamps and arrival times (ns, system clock), one per
    JointState in arrival order, and the index of the topic each came on (empty: one topic)."""

    stamp_ns: np.ndarray
    arrival_ns: np.ndarray
    topic_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    # the stage topics' messages (``--stage-topics``): stamp, arrival (ns) and topic index
    stage_stamp_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    stage_arrival_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    stage_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def of_topic(self, index: int) -> ProbeRecord:
        """The JointStates that came on the probe's topic ``index`` only."""
        if len(self.topic_index) != len(self.stamp_ns):
            return self if index == 0 else ProbeRecord(self.stamp_ns[:0], self.arrival_ns[:0])
        keep = self.topic_index == index
        return ProbeRecord(self.stamp_ns[keep], self.arrival_ns[keep])

    @property
    def latencies_s(self) -> np.ndarray:
        """Arrival minus header stamp, seconds."""
        return (self.arrival_ns - self.stamp_ns) * 1e-9

    def stage_latencies_s(self, index: int) -> np.ndarray:
        """Arrival minus header stamp (seconds) of the messages of stage topic ``index``."""
        keep = self.stage_index == index
        return (self.stage_arrival_ns[keep] - self.stage_stamp_ns[keep]) * 1e-9

    @property
    def rate_hz(self) -> float:
        """JointStates per second between the first and the last arrival (0 if < 2)."""
        if len(self.arrival_ns) < 2:
            return 0.0
        span = (self.arrival_ns[-1] - self.arrival_ns[0]) * 1e-9
        return (len(self.arrival_ns) - 1) / span if span > 0 else 0.0


def window_summaries(record: ProbeRecord, window_s: float) -> list[dict[str, float]]:
    """Rate and latency p50/p95/max per consecutive ``window_s`` window of arrival time."""
    if len(record.arrival_ns) == 0:
        return []
    t = (record.arrival_ns - record.arrival_ns[0]) * 1e-9
    latency_ms = record.latencies_s * 1e3
    rows = []
    for k in range(int(t[-1] // window_s) + 1):
        inside = (t >= k * window_s) & (t < (k + 1) * window_s)
        if not inside.any():
            continue
        values = latency_ms[inside]
        rows.append({'window_start_s': k * window_s, 'joint_states': int(inside.sum()),
                     'rate_hz': float(inside.sum() / window_s),
                     'latency_p50_ms': float(np.percentile(values, 50)),
                     'latency_p95_ms': float(np.percentile(values, 95)),
                     'latency_max_ms': float(values.max())})
    return rows


class ProbeError(ColorGloveError, RuntimeError):
    """The latency probe's process did not start, ended before the run did, or wrote no
    record: the run has no latency figures."""


class LatencyProbe:
    """The probe as a separate process: ``start()``, run the pipeline, ``stop()`` -> record."""

    def __init__(self, env: dict[str, str] | None = None,
                 topics: Sequence[str] = (JOINT_STATES_TOPIC,),
                 stage_topics: Sequence[tuple[str, str]] = ()) -> None:
        self.env = env
        self.topics = tuple(topics)
        # (topic, message type such as 'colorglove_msgs/msg/HandObservation') of the stages
        self.stage_topics = tuple(stage_topics)
        self.folder = tempfile.TemporaryDirectory(prefix='latency_probe_')
        self.output = Path(self.folder.name) / 'record.json'
        self.process: subprocess.Popen | None = None
        self.first_file = Path(self.folder.name) / 'first'

    def start(self, ready_timeout_s: float = 30.0) -> None:
        """Start the process and wait until it has subscribed."""
        ready = Path(self.folder.name) / 'ready'
        with signal_exit.deferred():       # a started probe is always recorded
            self.process = subprocess.Popen(
                [sys.executable, '-m', 'colorglove_ros.ros.latency_probe', '--output',
                 str(self.output), '--ready-file', str(ready), '--first-file',
                 str(self.first_file), '--topics', *self.topics,
                 *(['--stage-topics', *(f'{topic}={kind}' for topic, kind in self.stage_topics)]
                   if self.stage_topics else [])], env=self.env)
        deadline = time.monotonic() + ready_timeout_s
        while not ready.exists():
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise ProbeError('the latency probe did not start')
            time.sleep(0.05)

    def wait_for_first(self, timeout_s: float) -> bool:
        """Wait until the first JointState has arrived; False after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not self.first_file.exists():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.05)
        return True

    def failure(self) -> str:
        """Why the started process is no longer running (its exit code), '' while it runs."""
        if self.process is None:
            return 'the latency probe was not started'
        code = self.process.poll()
        if code is None:
            return ''
        how = f'was killed by signal {-code}' if code < 0 else f'exited with code {code}'
        return f'the latency probe (pid {self.process.pid}) {how} before the run ended'

    def cpu_seconds(self) -> float:
        """CPU time (user + system, seconds) the running process has used so far;
        :class:`ProbeError` if it has ended."""
        from colorglove_ros.ros.launcher import process_cpu_seconds

        failure = self.failure()
        if not failure:
            try:
                return process_cpu_seconds(self.process.pid)
            except OSError:         # ended (and was reaped) after the poll
                failure = self.failure() or 'the latency probe ended before the run did'
        raise ProbeError(failure)

    def stop(self, timeout_s: float = 10.0) -> ProbeRecord:
        """Stop the process (SIGINT) and return what it recorded; :class:`ProbeError` if it
        had already ended (it then wrote no record) or wrote none."""
        failure = self.failure()
        if failure:
            self.close()
            raise ProbeError(failure)
        self._end_process(timeout_s)
        try:
            data = json.loads(self.output.read_text())
        except (OSError, ValueError) as exc:
            raise ProbeError(f'the latency probe wrote no record: {exc}') from exc
        finally:
            self.folder.cleanup()
        return ProbeRecord(*(np.asarray(data[key], np.int64) for key in (
            'stamp_ns', 'arrival_ns', 'topic_index', 'stage_stamp_ns', 'stage_arrival_ns',
            'stage_index')))

    def close(self, timeout_s: float = 2.0) -> None:
        """End the process without reading its record (a run that failed or was stopped):
        SIGINT first, so it leaves DDS cleanly (no shared-memory segments left behind), SIGKILL
        after ``timeout_s``; nothing is left running, and the folder is removed."""
        self._end_process(timeout_s)
        self.folder.cleanup()

    def _end_process(self, timeout_s: float) -> None:
        """SIGINT the running process (it then writes its record and leaves DDS cleanly);
        SIGKILL it if it has not exited after ``timeout_s``."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def main(argv: list[str] | None = None) -> int:
    """Subscribe to /hand/joint_states (or --topics) and record stamp and arrival of each
    message."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--output', type=Path, required=True, help='JSON file written at exit')
    parser.add_argument('--duration', type=float, default=0.0, help='seconds (0: until SIGINT)')
    parser.add_argument('--ready-file', type=Path, help='touched once subscribed')
    parser.add_argument('--first-file', type=Path, help='touched on the first JointState')
    parser.add_argument('--topics', nargs='+', default=[JOINT_STATES_TOPIC],
                        help='JointState topics to record')
    parser.add_argument('--stage-topics', nargs='*', default=[],
                        type=topic_argument('TYPE', str), metavar='TOPIC=TYPE',
                        help='also record the stamp and arrival of these topics\' messages '
                             '(types whose messages start with a std_msgs/Header, e.g. '
                             'colorglove_msgs/msg/HandObservation), taken serialized')
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from sensor_msgs.msg import JointState

    from colorglove_ros.ros.lean_executor import LeanExecutor

    stamps: list[int] = []
    arrivals: list[int] = []
    topic_index: list[int] = []
    stage = {'stage_stamp_ns': [], 'stage_arrival_ns': [], 'stage_index': []}

    def on_stage(data: bytes, index: int) -> None:
        stage['stage_arrival_ns'].append(time.time_ns())
        sec, nanosec = header_stamp_from_cdr(data)
        stage['stage_stamp_ns'].append(sec * 1_000_000_000 + nanosec)
        stage['stage_index'].append(index)

    def on_joints(msg: JointState, index: int) -> None:
        arrivals.append(time.time_ns())
        stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
        topic_index.append(index)
        if len(arrivals) == 1 and args.first_file is not None:
            args.first_file.touch()

    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node('latency_probe')
    qos = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=100,
                     reliability=QoSReliabilityPolicy.RELIABLE)
    for index, topic in enumerate(args.topics):
        node.create_subscription(JointState, topic,
                                 lambda msg, index=index: on_joints(msg, index), qos)
    if args.stage_topics:   # only then these modules (the probe starts lean without)
        from colorglove_ros.ros.image_codec import header_stamp_from_cdr
        from colorglove_ros.ros.typestore import message_class
    for index, (topic, kind) in enumerate(args.stage_topics):
        node.create_subscription(message_class(kind), topic,
                                 lambda data, index=index: on_stage(data, index), qos, raw=True)
    if args.ready_file is not None:
        args.ready_file.touch()
    deadline = time.monotonic() + args.duration if args.duration > 0 else float('inf')
    # the nodes' executor: rclpy.spin_once would add the node to the global executor and
    # remove it again on every wake, CPU taken from the cores the measured graph shares
    executor = LeanExecutor()
    executor.add_node(node)
    try:
        while not stop and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    tmp = args.output.with_suffix('.tmp')
    tmp.write_text(json.dumps({'stamp_ns': stamps, 'arrival_ns': arrivals,
                               'topic_index': topic_index, **stage}))
    os.replace(tmp, args.output)
    return 0


if __name__ == '__main__':
    sys.exit(main())
