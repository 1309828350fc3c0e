"""In-process time per pipeline stage: the real node classes (segmentation, lookup, ik) built in
one process on their own context, fed a bag's frames one at a time by calling their callbacks,
each stage's output serialised and deserialised as DDS would carry it to the next.

A stage's time is the deserialisation of its input (none for the segmentation, which takes its
images serialized) plus its callback (decoding, the core's
work, message conversion and the publish that serialises its output); the core's own compute
time (what the stage reports in its messages) is kept beside it. With a profiler per stage
(``cProfile``) the same run says where the time goes. No executor spins: nothing is queued or
dropped, so every frame is measured."""
from __future__ import annotations

import cProfile
import gc
import io
import pstats
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from colorglove_ros.ros.image import array_to_image

__all__ = ['STAGE_NAMES', 'StageTimes', 'profile_stages', 'stage_summary', 'passes_summary',
           'frames_of_bag']

#: The timed stages, in pipeline order.
STAGE_NAMES = ('segmentation', 'lookup', 'ik')


@dataclass
class StageTimes:
    """Per frame: each stage's node time (input deserialisation + callback, ms; wall and the
    thread's CPU time, which other processes on the machine disturb less), each stage's
    own compute time as it reports it (ms, NaN when it did not run), and whether a JointState
    came out; optional ``cProfile`` statistics per stage."""

    node_ms: dict[str, list[float]] = field(
        default_factory=lambda: {name: [] for name in STAGE_NAMES})
    cpu_ms: dict[str, list[float]] = field(
        default_factory=lambda: {name: [] for name in STAGE_NAMES})
    compute_ms: dict[str, list[float]] = field(
        default_factory=lambda: {name: [] for name in STAGE_NAMES})
    tracked: list[bool] = field(default_factory=list)
    profiles: dict[str, pstats.Stats] = field(default_factory=dict)

    def frame_ms(self, cpu: bool = False) -> np.ndarray:
        """Node time (``cpu``: CPU time) of the three stages together, per frame."""
        table = self.cpu_ms if cpu else self.node_ms
        return np.sum([table[name] for name in STAGE_NAMES], axis=0)


class _Last:
    """Wraps a publisher's ``publish`` to keep the last message published."""

    def __init__(self, publisher: Any) -> None:
        self.message = None
        self._publish = publisher.publish
        publisher.publish = self

    def __call__(self, message: Any) -> None:
        self._publish(message)
        self.message = message

    def take(self) -> Any:
        message, self.message = self.message, None
        return message


def _overrides(values: dict[str, Any]) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


def frames_of_bag(bag: Path, limit: int | None = None) -> list[tuple[int, np.ndarray]]:
    """(stamp ns, RGB image) of a sequence bag's frames, in order (at most ``limit``)."""
    from colorglove_ros.ros.bags import read_sequence_bag

    frames = []
    for frame in read_sequence_bag(bag):
        if frame.image_rgb is not None:
            frames.append((frame.stamp_ns, frame.image_rgb))
            if limit is not None and len(frames) >= limit:
                break
    return frames


def profile_stages(frames: Iterable[tuple[int, np.ndarray]], parameters: dict[str, dict],
                   *, profile: bool = False, frame_id: str = 'camera_optical_frame'
                   ) -> StageTimes:
    """Run ``frames`` ((stamp ns, RGB image)) through segmentation_node, lookup_node and ik_node
    built in this process with ``parameters`` ({node name: {parameter: value}}; the nodes read
    their camera from ``calibration_file``, not CameraInfo) and time each stage. The nodes
    are freed before it returns (their reference cycles collected), so passes run one after
    another each start with one set of nodes in memory, as a node process holds."""
    try:
        return _profile_stages(frames, parameters, profile, frame_id)
    finally:
        gc.collect()


def _profile_stages(frames: Iterable[tuple[int, np.ndarray]], parameters: dict[str, dict],
                    profile: bool, frame_id: str) -> StageTimes:
    from colorglove_ros.ros.nodes.ik_node import IKNode
    from colorglove_ros.ros.nodes.lookup_node import LookupNode
    from colorglove_ros.ros.nodes.segmentation_node import SegmentationNode

    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = []
    times = StageTimes()
    profilers = {name: cProfile.Profile() for name in STAGE_NAMES} if profile else {}
    try:
        for cls, name in ((SegmentationNode, 'segmentation'), (LookupNode, 'lookup'),
                          (IKNode, 'ik')):
            values = {**parameters.get(name, {}), 'use_camera_info': False}
            nodes.append(cls(context=context, parameter_overrides=_overrides(values)))
        segmentation, lookup, ik = nodes
        observation = _Last(segmentation.publisher)
        candidates = _Last(lookup.publisher)
        joints = _Last(ik.outputs.pose.joints)
        status = _Last(ik.outputs.status)
        for stamp_ns, rgb in frames:
            header = Header(frame_id=frame_id)
            header.stamp.sec, header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
            wire = serialize_message(array_to_image(rgb, 'rgb8', header))
            # segmentation_node takes its images serialized (a raw subscription)
            steps = ((segmentation.on_serialized_image, observation),
                     (lookup.on_observation, candidates), (ik.on_candidates, None))
            message_type = None
            for name, (callback, output) in zip(STAGE_NAMES, steps, strict=True):
                prof = profilers.get(name)
                started, cpu = time.perf_counter(), time.thread_time()
                if prof is not None:
                    prof.enable()
                callback(wire if message_type is None else deserialize_message(wire, message_type))
                if prof is not None:
                    prof.disable()
                times.node_ms[name].append(1e3 * (time.perf_counter() - started))
                times.cpu_ms[name].append(1e3 * (time.thread_time() - cpu))
                if output is not None:
                    message = output.take()
                    message_type = type(message)
                    wire = serialize_message(message)
                    _compute(times, name, message)
            text = status.take()
            times.compute_ms['ik'].append(_ik_ms(text.data if text is not None else ''))
            times.tracked.append(joints.take() is not None)
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    for name, prof in profilers.items():
        times.profiles[name] = pstats.Stats(prof)
    return times


def _compute(times: StageTimes, name: str, message: Any) -> None:
    if name == 'segmentation':
        times.compute_ms[name].append(float(message.processing_time_ms))
    else:
        ran = message.lookup_time_ms > 0.0
        times.compute_ms[name].append(float(message.lookup_time_ms) if ran else float('nan'))


def _ik_ms(status: str) -> float:
    from colorglove_ros.ros.pipeline_run import ik_times_ms

    found = ik_times_ms([status])
    return found[0] if found else float('nan')


def stage_summary(times: StageTimes) -> list[dict[str, Any]]:
    """One row per stage and one for the whole frame: node time (wall and CPU) and the stage's
    own compute time, median and p95 (ms), over the frames where the stage ran."""
    def percentiles(values: Sequence[float]) -> tuple[float, float]:
        values = np.asarray(values, float)
        values = values[np.isfinite(values)]
        if not len(values):
            return float('nan'), float('nan')
        return float(np.median(values)), float(np.percentile(values, 95))

    rows = []
    for name in STAGE_NAMES:
        rows.append(_row(name, percentiles(times.node_ms[name]),
                         percentiles(times.cpu_ms[name]), percentiles(times.compute_ms[name])))
    total = np.nansum([times.compute_ms[name] for name in STAGE_NAMES], axis=0)
    rows.append(_row('frame', percentiles(times.frame_ms()), percentiles(times.frame_ms(True)),
                     percentiles(total)))
    return rows


def passes_summary(passes: Sequence[StageTimes]) -> tuple[list[dict[str, Any]],
                                                         list[dict[str, Any]]]:
    """Several passes over the same frames (each through fresh nodes): the
    :func:`stage_summary` rows with every figure the median over the passes of that pass's
    figure (so the frame row's ``node_p50_ms`` is the median of the passes' per-frame
    medians), and one row per pass with its per-frame medians (frame wall and CPU, each stage's
    node time) and its tracked frames."""
    if not passes:
        raise ValueError('passes_summary needs at least one pass')
    summaries = [stage_summary(times) for times in passes]
    rows = [{key: (row[key] if key == 'stage' else
                   float(np.median([summary[i][key] for summary in summaries])))
             for key in row} for i, row in enumerate(summaries[0])]
    per_pass = []
    for number, (summary, times) in enumerate(zip(summaries, passes, strict=True), start=1):
        by_stage = {row['stage']: row for row in summary}
        per_pass.append({'pass': number, 'frame_p50_ms': by_stage['frame']['node_p50_ms'],
                         'frame_cpu_p50_ms': by_stage['frame']['node_cpu_p50_ms'],
                         **{f'{name}_p50_ms': by_stage[name]['node_p50_ms']
                            for name in STAGE_NAMES},
                         'tracked': int(sum(times.tracked))})
    return rows, per_pass


def _row(stage: str, node: tuple[float, float], cpu: tuple[float, float],
         compute: tuple[float, float]) -> dict[str, Any]:
    return {'stage': stage, 'node_p50_ms': node[0], 'node_p95_ms': node[1],
            'node_cpu_p50_ms': cpu[0], 'node_cpu_p95_ms': cpu[1],
            'compute_p50_ms': compute[0], 'compute_p95_ms': compute[1]}


def profile_text(stats: pstats.Stats, lines: int = 25) -> str:
    """The ``lines`` functions with the most cumulative time, as text."""
    out = io.StringIO()
    stats.stream = out
    stats.sort_stats('cumulative').print_stats(lines)
    return out.getvalue()


__all__ += ['profile_text']
