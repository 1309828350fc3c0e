"""Run the four tracker nodes as separate processes over DDS and measure them: frames tracked,
rate, latency from camera frame to JointState, and accuracy against ground truth. Shared by the
demo, the benchmark, the soak test and the end-to-end test.

Latency and rate come from a lean subscriber in its own process (``ros.latency_probe``:
JointState arrival minus the camera frame's header stamp); the per-stage figures are the
processing times the stages measure themselves and carry in their messages (segmentation and
lookup times in ``HandPoseCandidates``, the IK time in the tracking status), never arrival
times in the monitor. The monitor learns which frames were offered from each frame's
``CameraInfo`` (the camera node and the bag player publish one with the image's stamp for
every frame), not from the 1 MB image, so it costs the measured graph little CPU."""
from __future__ import annotations

import os
import re
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
import yaml
from colorglove_msgs.msg import HandObservation, HandPoseCandidates
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String

from colorglove_ros.core.evaluation.metrics import jitter_runs_mm, latency_summary_ms, pose_accuracy
from colorglove_ros.core.segmentation.calibration_fit import (
    DEFAULT_COLOR_CONFIG,
    prepared_color_config,
)
from colorglove_ros.ros.conversions import pose_from_msgs, stamp_key
from colorglove_ros.ros.frame_camera import CAMERA_REFUSAL_PREFIX
from colorglove_ros.ros.image import image_to_rgb8
from colorglove_ros.ros.image_codec import header_stamp_from_cdr
from colorglove_ros.ros.latency_probe import LatencyProbe, ProbeError, ProbeRecord
from colorglove_ros.ros.launcher import (
    Launcher,
    NodeSpec,
    use_fastdds_profile,
)
from colorglove_ros.ros.lean_executor import LeanExecutor

__all__ = ['BagFeed', 'CAMERA_INFO_SUBSCRIBERS', 'IMAGE_SUBSCRIBERS', 'PipelineMonitor',
           'PipelineRun', 'bag_feed', 'node_specs', 'run_pipeline',
           'summarize', 'ik_times_ms', 'DATABASE_CONFIG',
           'prepare_assets', 'pipeline_parameters', 'write_params', 'STAGE_OUTPUTS']

DATABASE_CONFIG = 'config/database.yaml'

# ik_node's status line of a tracked frame ends with "IK <time> ms"
_IK_TIME = re.compile(r'IK (\d+(?:\.\d+)?) ms')

_RELIABLE = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=200,
                       reliability=QoSReliabilityPolicy.RELIABLE)
_BEST_EFFORT = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=200,
                          reliability=QoSReliabilityPolicy.BEST_EFFORT)


def _key(msg: Any) -> tuple[int, int]:
    return stamp_key(msg.header.stamp)


class PipelineMonitor(Node):
    """Records, with receive times, the camera frames offered (one ``CameraInfo`` per frame,
    stamped as its image; those stamped before the monitor started are not this run's),
    ground truth and the tracker's outputs."""

    def __init__(self, keep_overlays: int = 8, overlay_stride: int = 10, **kwargs) -> None:
        super().__init__('pipeline_monitor', **kwargs)
        self.lock = threading.Lock()
        self.frame_times: dict[tuple[int, int], float] = {}
        self.output_times: dict[tuple[int, int], float] = {}
        self.joints: dict[tuple[int, int], JointState] = {}
        self.wrists: dict[tuple[int, int], PoseStamped] = {}
        self.truth_joints: dict[tuple[int, int], JointState] = {}
        self.truth_wrists: dict[tuple[int, int], PoseStamped] = {}
        self.lookup_ms: dict[tuple[int, int], float] = {}
        self.segmentation_ms: dict[tuple[int, int], float] = {}
        self.observation_times: dict[tuple[int, int], float] = {}
        self.camera_refusals: list[str] = []     # observations refused for their camera model
        self.candidate_times: dict[tuple[int, int], float] = {}
        self.overlays: list[np.ndarray] = []
        self.statuses: list[str] = []
        self.keep_overlays = keep_overlays
        self.overlay_stride = overlay_stride
        self.overlay_count = 0
        # system clock, as the camera and the bag player (--restamp) stamp frames: an older
        # CameraInfo is a bag's first one, primed as recorded, or a previous run's
        self.started = stamp_key(self.get_clock().now().to_msg())
        # reliable, as camera_node and the bag player publish: a frame the graph drops must
        # still count as offered
        self.create_subscription(CameraInfo, '/camera/camera_info', self._on_frame, _RELIABLE,
                                 raw=True)
        self.create_subscription(JointState, '/hand/joint_states', self._on_joints, _RELIABLE)
        self.create_subscription(PoseStamped, '/hand/wrist_pose', self._store(self.wrists),
                                 _RELIABLE)
        self.create_subscription(JointState, '/hand/ground_truth/joint_states',
                                 self._store(self.truth_joints), _RELIABLE)
        self.create_subscription(PoseStamped, '/hand/ground_truth/wrist_pose',
                                 self._store(self.truth_wrists), _RELIABLE)
        self.create_subscription(HandPoseCandidates, '/hand/pose_candidates',
                                 self._on_candidates, _RELIABLE)
        self.create_subscription(HandObservation, '/hand/observation', self._on_observation,
                                 _RELIABLE)
        self.create_subscription(Image, '/hand/overlay', self._on_overlay, _BEST_EFFORT,
                                 raw=True)
        self.create_subscription(String, '/hand/tracking_status', self._on_status, _RELIABLE)

    def _store(self, table: dict):
        def callback(msg: Any) -> None:
            with self.lock:
                table[_key(msg)] = msg
        return callback

    def _on_frame(self, data: bytes) -> None:
        received = time.monotonic()
        stamp = header_stamp_from_cdr(data)
        if stamp < self.started:
            return
        with self.lock:
            self.frame_times.setdefault(stamp, received)

    def _on_joints(self, msg: JointState) -> None:
        received = time.monotonic()
        with self.lock:
            self.output_times.setdefault(_key(msg), received)
            self.joints[_key(msg)] = msg

    def _on_observation(self, msg: HandObservation) -> None:
        with self.lock:
            self.observation_times.setdefault(_key(msg), time.monotonic())
            if not msg.hand_found and msg.status.startswith(CAMERA_REFUSAL_PREFIX):
                self.camera_refusals.append(msg.status)

    def _on_candidates(self, msg: HandPoseCandidates) -> None:
        with self.lock:
            self.candidate_times.setdefault(_key(msg), time.monotonic())
            self.lookup_ms[_key(msg)] = msg.lookup_time_ms
            self.segmentation_ms[_key(msg)] = msg.observation.processing_time_ms

    def _on_status(self, msg: String) -> None:
        with self.lock:
            self.statuses.append(msg.data)

    def _on_overlay(self, data: bytes) -> None:
        self.overlay_count += 1
        wanted = self.overlay_count % self.overlay_stride == 0
        if wanted and len(self.overlays) < self.keep_overlays:
            self.overlays.append(image_to_rgb8(deserialize_message(data, Image)))

    def active_duration(self) -> float:
        """Seconds from the first to the last JointState received (0 if fewer than two)."""
        with self.lock:
            if len(self.output_times) < 2:
                return 0.0
            return max(self.output_times.values()) - min(self.output_times.values())

    def wait_for_frames(self, count: int, timeout_s: float, settle_s: float = 2.0) -> bool:
        """Wait until ``count`` frames were seen and outputs stopped arriving for ``settle_s``;
        False if ``timeout_s`` passed first."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self.lock:
                seen = len(self.frame_times)
                last = max(self.output_times.values(), default=0.0)
                last = max(last, max(self.frame_times.values(), default=0.0))
            if seen >= count and time.monotonic() - last > settle_s:
                return True
            time.sleep(0.1)
        return False


@dataclass
class PipelineRun:
    """What a run measured (see :func:`summarize`)."""

    frames_expected: int
    frames: int
    segmented: int
    tracked: int
    duration_s: float
    latencies_s: list[float]
    estimated: np.ndarray
    truth: np.ndarray
    segmentation_ms: list[float]
    lookup_ms: list[float]
    probe: ProbeRecord | None = None          # the lean subscriber's record (rate, latency)
    frame_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    timed_out: bool = False
    overlays: list[np.ndarray] = field(default_factory=list)
    statuses: list[str] = field(default_factory=list)      # ik_node's tracking status lines
    # segmentation's 'camera: ...' answers (e.g. a frame ahead of its CameraInfo)
    camera_refusals: list[str] = field(default_factory=list)
    # camera frames (header stamp sec, nanosec) the monitor saw that got no observation
    unsegmented: list[tuple[int, int]] = field(default_factory=list)
    feed_output: str = ''                     # what the feed (e.g. the bag player) printed
    # CPU time (seconds) while the feed ran, per node process (launcher label), 'monitor' (this
    # process: the monitor, the feed's thread), 'probe' (the latency probe's process) and
    # 'player' (the feed's process, whole run)
    cpu_s: dict[str, float] = field(default_factory=dict)
    # why the latency probe gave no record ('' if it ran to the end): the run has no latency
    probe_error: str = ''

    def missed_frames(self) -> str:
        """Why a run segmented fewer frames than it saw, for a failure message: the frames
        without an observation, the camera refusals and the feed's output."""
        return (f'{self.segmented} of {self.frames} camera frames segmented; without an '
                f'observation: {self.unsegmented}; camera refusals: {self.camera_refusals}; '
                f'feed output: {self.feed_output.strip()!r}')


def prepare_assets(database: Path | None = None) -> Path:
    """The pose database to run with (``database``, default the one ``config/database.yaml``
    names, built first if missing; a ``database`` given that does not exist is a
    :class:`DatabaseError`, not a build in a mistyped place), and the colour calibration
    ``config/color_calibration.yaml`` names, fitted first on rendered training frames if missing
    (each once)."""
    from colorglove_ros.core.lookup.database import DatabaseError, save_database
    from colorglove_ros.core.lookup.database_build import build_database, read_database_config

    config, default_database, _ = read_database_config(DATABASE_CONFIG)
    if database and not (Path(database) / 'manifest.json').is_file():
        raise DatabaseError(f'no pose database at {database} (no manifest.json): build one '
                            f'with `colorglove_build_database --output {database}`, or leave '
                            f'out --database to use the default {default_database} (built '
                            'there on first use)')
    database = Path(database) if database else default_database
    prepared_color_config(progress=lambda message: print(f'[demo] {message}', flush=True))
    if not (database / 'manifest.json').is_file():
        print(f'[demo] no pose database at {database}: building it (once; the default '
              '100,000 entries take several minutes on 2 cores)', flush=True)
        started = time.perf_counter()
        db = build_database(config, progress=lambda message: print(f'[build] {message}',
                                                                    flush=True))
        save_database(db, database)
        print(f'[demo] pose database of {len(db)} entries saved at {database} '
              f'({time.perf_counter() - started:.0f} s)', flush=True)
    return database


def pipeline_parameters(database: Path, seed: int, frames: int, rate_hz: float,
                        calibration: str = 'config/calibration.yaml') -> dict[str, dict]:
    """Node parameters of a run on synthetic sequence ``seed`` (``frames`` frames offered at
    ``rate_hz`` by camera_node) with pose database ``database``."""
    return {
        'camera': {'source': 'synthetic', 'synthetic_seed': seed, 'synthetic_frames': frames,
                   'synthetic_prerender': True, 'loop': False, 'rate_hz': rate_hz,
                   'calibration_file': calibration},
        'segmentation': {'color_calibration_file': DEFAULT_COLOR_CONFIG},
        'lookup': {'database_path': str(database), 'calibration_file': calibration},
        'ik': {'database_path': str(database), 'calibration_file': calibration,
               'publish_overlay': True},
    }


def node_specs(params_file: Path, with_camera: bool, single_process: bool = False
               ) -> list[NodeSpec]:
    """The tracker's node processes, all reading ``params_file``; with ``single_process`` one
    process running every node (``colorglove_single_process``)."""
    if single_process:
        return [NodeSpec('colorglove_single_process', '', [params_file],
                         arguments=[] if with_camera else ['--no-camera'])]
    names = [('segmentation_node', 'segmentation'), ('lookup_node', 'lookup'), ('ik_node', 'ik')]
    if with_camera:
        names.insert(0, ('camera_node', 'camera'))
    return [NodeSpec(executable, name, [params_file]) for executable, name in names]


def looping_pipeline(database: Path | None, seed: int, frames: int, rate_hz: float,
                     folder: Path) -> tuple[Any, Path]:
    """A launcher (not started) of the four nodes on synthetic sequence ``seed`` looped at
    ``rate_hz`` without overlays, its parameter file in ``folder``, with the Fast DDS profile
    set; and the pose database it runs with (see :func:`prepare_assets`)."""
    from colorglove_ros.ros.launcher import Launcher, use_fastdds_profile

    database = prepare_assets(database)
    parameters = pipeline_parameters(database, seed, frames, rate_hz)
    parameters['camera']['loop'] = True
    parameters['ik']['publish_overlay'] = False
    use_fastdds_profile()
    return Launcher(node_specs(write_params(parameters, folder), True)), database


def write_params(parameters: dict[str, dict[str, Any]], folder: Path) -> Path:
    """A ROS 2 parameter file from {node name: {parameter: value}}."""
    path = folder / 'params.yaml'
    # copies: a dict shared by two nodes would become a YAML alias, which rcl refuses
    path.write_text(yaml.safe_dump({name: {'ros__parameters': dict(values)}
                                    for name, values in parameters.items()}))
    return path


def run_pipeline(parameters: dict[str, dict[str, Any]], expected_frames: int,
                 feed: Any = None, timeout_s: float = 600.0, startup_s: float = 60.0,
                 keep_overlays: int = 8, extra_nodes: Sequence[NodeSpec] = (),
                 extra_inputs: dict[str, str] | None = None,
                 single_process: bool = False,
                 stage_topics: Sequence[tuple[str, str]] = ()) -> PipelineRun:
    """Start the nodes with ``parameters`` (camera_node too unless ``feed`` is given: a
    callable started once the graph is up, e.g. a bag player), monitor until
    ``expected_frames`` frames passed, stop everything, and return the measurements.
    ``extra_nodes`` (e.g. a second camera's segmentation_node) also read the parameter file;
    ``extra_inputs`` maps their input topics to their node names, awaited like the stages'.
    With ``single_process`` the tracker's nodes run in one process (:func:`node_specs`).
    ``stage_topics`` ((topic, type), e.g. :data:`STAGE_OUTPUTS`) are also recorded by the
    latency probe (``ProbeRecord.stage_latencies_s``). A latency probe that ended before the
    run did ends nothing else: the run then has an empty record, NaN probe CPU and the reason
    in ``probe_error``."""
    use_fastdds_profile()
    with tempfile.TemporaryDirectory() as folder:
        params_file = write_params(parameters, Path(folder))
        context = rclpy.Context()
        rclpy.init(context=context)
        monitor = PipelineMonitor(keep_overlays=keep_overlays,
                                  overlay_stride=max(1, expected_frames // (keep_overlays + 1)),
                                  context=context)
        # one thread: the monitor's callbacks only record, and rclpy's multi-threaded executor
        # costs more CPU per message, taken from the cores the measured graph shares
        # (docs/RESULTS.md, issue 19, sixth pass); the nodes' lean one costs less again
        executor = LeanExecutor(context=context)
        executor.add_node(monitor)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        launcher = Launcher(node_specs(params_file, feed is None, single_process) + [
            replace(spec, parameters=[params_file, *spec.parameters]) for spec in extra_nodes])
        probe = LatencyProbe(stage_topics=stage_topics)
        record = None
        probe_errors: list[str] = []
        cpu_s: dict[str, float] = {}
        try:
            probe.start()
            if feed is not None:
                launcher.start()
                _wait_for_graph(monitor, startup_s, {**STAGE_INPUTS, **(extra_inputs or {})})
                def cpu_now() -> dict[str, float]:
                    # the node processes, this process (the monitor) and the latency probe
                    return {**launcher.cpu_seconds(), 'monitor': time.process_time(),
                            'probe': _probe_cpu_seconds(probe, probe_errors)}

                started = time.monotonic()
                cpu_before = cpu_now()
                feeder = threading.Thread(target=feed, daemon=True)
                feeder.start()
                feeder.join(timeout_s)
                # the feed has ended: wait for the last outputs (no frame count needed)
                completed = not feeder.is_alive() and monitor.wait_for_frames(0, 60.0)
                cpu_s = _cpu_since(cpu_before, cpu_now())
                cpu_s['player'] = float(getattr(feed, 'cpu_s', float('nan')))
            else:
                started = time.monotonic()
                launcher.start()
                completed = monitor.wait_for_frames(expected_frames, timeout_s)
            duration = monitor.active_duration() or time.monotonic() - started
            try:
                record = probe.stop()
            except ProbeError as exc:
                probe_errors.append(str(exc))
                record = ProbeRecord(np.zeros(0, np.int64), np.zeros(0, np.int64))
        finally:
            if record is None:
                probe.close()
            launcher.stop()
            executor.shutdown()
            spinner.join(timeout=5.0)
            monitor.destroy_node()
            rclpy.try_shutdown(context=context)
    run = _collect(monitor, duration, expected_frames, record)
    run.timed_out = not completed
    run.feed_output = getattr(feed, 'output', '')
    run.cpu_s = cpu_s
    run.probe_error = probe_errors[0] if probe_errors else ''
    return run


def _probe_cpu_seconds(probe: LatencyProbe, errors: list[str]) -> float:
    """The probe process's CPU seconds so far; NaN, with the reason appended to ``errors``,
    if it has ended."""
    try:
        return probe.cpu_seconds()
    except ProbeError as exc:
        errors.append(str(exc))
        return float('nan')


def _cpu_since(before: dict[str, float], after: dict[str, float]) -> dict[str, float]:
    """CPU seconds used between two readings, for what both readings hold."""
    return {name: after[name] - before[name] for name in before if name in after}


# Each stage's input topic and the node that must subscribe to it before frames flow.
STAGE_INPUTS = {'/camera/image_raw': 'segmentation', '/hand/observation': 'lookup',
                '/hand/pose_candidates': 'ik'}


# The stages' outputs (topic, type) the probe can record beside the JointStates: when a frame's
# observation and candidates arrive, from its camera stamp.
STAGE_OUTPUTS = (('/hand/observation', 'colorglove_msgs/msg/HandObservation'),
                 ('/hand/pose_candidates', 'colorglove_msgs/msg/HandPoseCandidates'))


def _wait_for_graph(monitor: PipelineMonitor, timeout_s: float, inputs: dict[str, str]) -> None:
    """Wait until every node of ``inputs`` (input topic -> node name) subscribes to its
    input topic."""
    deadline = time.monotonic() + timeout_s
    missing = dict(inputs)
    while time.monotonic() < deadline:
        missing = {topic: node for topic, node in inputs.items()
                   if node not in {info.node_name
                                   for info in monitor.get_subscriptions_info_by_topic(topic)}}
        if not missing:
            return
        time.sleep(0.2)
    raise TimeoutError(f'the tracker nodes did not come up within {timeout_s:.0f} s: '
                       f'no subscriber {missing}')


def _collect(monitor: PipelineMonitor, duration: float, published: int,
             record: ProbeRecord) -> PipelineRun:
    with monitor.lock:
        matched = [k for k in sorted(monitor.joints) if k in monitor.wrists
                   and k in monitor.truth_joints and k in monitor.truth_wrists]
        estimated = np.array([pose_from_msgs(monitor.joints[k], monitor.wrists[k])
                              for k in matched])
        # position of each matched frame among all camera frames seen, in stamp order
        frame_order = {k: i for i, k in enumerate(sorted(monitor.frame_times))}
        frame_index = np.array([frame_order.get(k, -1) for k in matched], dtype=int)
        truth = np.array([pose_from_msgs(monitor.truth_joints[k], monitor.truth_wrists[k])
                          for k in matched])
        return PipelineRun(
            frames_expected=published, frames=len(monitor.frame_times),
            segmented=len(monitor.observation_times), tracked=len(monitor.joints),
            duration_s=duration,
            latencies_s=[float(v) for v in record.latencies_s],
            estimated=estimated.reshape(-1, 26),
            truth=truth.reshape(-1, 26),
            segmentation_ms=list(monitor.segmentation_ms.values()),
            lookup_ms=list(monitor.lookup_ms.values()), probe=record,
            frame_index=frame_index,
            overlays=list(monitor.overlays), statuses=list(monitor.statuses),
            camera_refusals=list(monitor.camera_refusals),
            unsegmented=sorted(set(monitor.frame_times) - set(monitor.observation_times)))


def ik_times_ms(statuses: Sequence[str]) -> list[float]:
    """The IK times ik_node reports in its status lines of tracked frames."""
    return [float(m.group(1)) for m in map(_IK_TIME.search, statuses) if m]


def summarize(run: PipelineRun, model) -> dict[str, float]:
    """The figures of a run: counts, rate, latency percentiles, stage times, accuracy."""
    latency = latency_summary_ms(run.latencies_s)
    figures = {
        'frames_expected': run.frames_expected, 'frames_seen_by_monitor': run.frames,
        'frames_segmented': run.segmented, 'frames_tracked': run.tracked,
        'frames_refused_for_camera': len(run.camera_refusals),
        'tracked_fraction': run.tracked / run.frames_expected if run.frames_expected else 0.0,
        # JointStates per second between the first and the last one the probe received
        'output_rate_hz': run.probe.rate_hz if run.probe is not None else 0.0,
        # the lean probe: JointState arrival minus the camera frame's header stamp
        'latency_mean_ms': latency['mean'], 'latency_p50_ms': latency['p50'],
        'latency_p95_ms': latency['p95'],
        'frames_with_truth': len(run.truth),
    }
    # CPU time per offered frame of each process while the feed ran (``PipelineRun.cpu_s``)
    for name, seconds in run.cpu_s.items():
        figures[f'cpu_ms_per_frame_{name}'] = (1e3 * seconds / run.frames_expected
                                               if run.frames_expected else float('nan'))
    # each stage's own processing time, carried in its messages
    for stage, times in (('segmentation', run.segmentation_ms), ('lookup', run.lookup_ms),
                         ('ik', ik_times_ms(run.statuses))):
        figures[f'{stage}_compute_mean_ms'] = _mean(times)
        figures[f'{stage}_compute_p95_ms'] = (float(np.percentile(times, 95)) if times
                                             else float('nan'))
    if len(run.truth):
        figures.update(pose_accuracy(model, run.estimated, run.truth))
        # frames missing from the output break the 5-frame windows: jitter over unbroken runs
        valid = run.frame_index >= 0
        tracked = np.zeros(run.frames, bool)
        tracked[run.frame_index[valid]] = True
        for key, poses in (('jitter_mm', run.estimated), ('jitter_truth_mm', run.truth)):
            on_grid = np.zeros((run.frames, 26))
            on_grid[run.frame_index[valid]] = poses[valid]
            figures[key] = jitter_runs_mm(model, on_grid, tracked)
    return figures


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else float('nan')


# Subscribers a played bag waits for before its first frame: the camera image's
# (segmentation_node) and its CameraInfo's (segmentation, lookup and IK each read it: one
# matched late answers the short bag 'waiting for CameraInfo'; and the monitor, which counts
# the frames offered by it)
IMAGE_SUBSCRIBERS = 1
CAMERA_INFO_SUBSCRIBERS = 4


class BagFeed:
    """A feed for :func:`run_pipeline`: play ``bag`` with ``colorglove_play_bag`` (a separate
    process) at ``rate`` times its original timing, or paced by the tracker's output; what the
    player printed (frames resent, warnings) is kept in ``output``. Before the first frame the
    player waits for :data:`IMAGE_SUBSCRIBERS` on the image, :data:`CAMERA_INFO_SUBSCRIBERS`
    on its CameraInfo and, for each topic of ``waits``, that many subscribers (e.g. a second
    camera's image and CameraInfo). ``pace_timeout_s`` (paced only) replaces the player's
    longest wait for an output before it resends a frame and goes on."""

    def __init__(self, bag: Path, rate: float = 1.0, paced: bool = False,
                 waits: dict[str, int] | None = None,
                 pace_timeout_s: float | None = None) -> None:
        import shutil

        player = shutil.which('colorglove_play_bag')
        if player is None:
            raise FileNotFoundError('colorglove_play_bag not on PATH (is the venv active?)')
        # restamped at publish time: the latency probe takes arrival minus header stamp, and
        # the monitor ignores CameraInfo stamped before it started (the primed first one)
        self.command = [player, str(bag), '--rate', str(rate),
                        '--min-subscribers', str(IMAGE_SUBSCRIBERS),
                        '--min-info-subscribers', str(CAMERA_INFO_SUBSCRIBERS), '--restamp'] + (
                            ['--paced'] if paced else []) + (
                            ['--pace-timeout', str(pace_timeout_s)]
                            if paced and pace_timeout_s is not None else []) + (
                            ['--wait-for', *(f'{topic}={count}' for topic, count in waits.items())]
                            if waits else [])
        self.output = ''
        # CPU time of the player process (user + system, seconds), its start-up included
        self.cpu_s = float('nan')

    def __call__(self) -> None:
        import subprocess

        with subprocess.Popen(self.command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True) as player:
            self.output = player.stdout.read()
            # reaped here, with its resource usage (Popen.wait gives none)
            _, status, usage = os.wait4(player.pid, 0)
            player.returncode = os.waitstatus_to_exitcode(status)
        self.cpu_s = usage.ru_utime + usage.ru_stime
        if player.returncode:
            raise subprocess.CalledProcessError(player.returncode, self.command, self.output)


def bag_feed(bag: Path, rate: float = 1.0, paced: bool = False,
             waits: dict[str, int] | None = None,
             pace_timeout_s: float | None = None) -> BagFeed:
    """A :class:`BagFeed` of ``bag`` (see there)."""
    return BagFeed(bag, rate, paced, waits, pace_timeout_s)
