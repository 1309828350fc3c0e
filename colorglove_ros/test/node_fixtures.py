"""Shared helpers for the node tests: the node assets (built once per session by conftest.py),
rendered frames and the messages the nodes make of them, an in-process node harness and a
runner for node processes."""
from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from repo_paths import CONFIG_DIR, REPO_DIR

BIN_DIR = Path(sys.executable).parent

RELIABLE = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)


# ------------------------------------------------------------------------------ assets
@dataclass(frozen=True)
class NodeAssets:
    """Files the nodes need: a colour config (+ calibration) and a small pose database."""

    color_config: Path
    calibration_npz: Path
    database: Path


def synthetic_color_config(folder: Path, frames: int, **options) -> tuple[Path, Path]:
    """A colour calibration fitted in ``folder`` on ``frames`` rendered training frames
    (``core.segmentation.calibration_fit.calibrate_synthetic`` with the fit ``options``);
    returns the calibration file and a colour config YAML naming it absolutely (the nodes
    resolve a config's relative paths against their working folder)."""
    from colorglove_ros.core.segmentation.calibration_fit import calibrate_synthetic

    fit = calibrate_synthetic(frames, folder / 'color_calibration.npz',
                              folder / 'calibration_frames', **options)
    lines = (CONFIG_DIR / 'color_calibration.yaml').read_text().splitlines()
    lines = [f'calibration_file: {fit.output}' if line.startswith('calibration_file:')
             else line for line in lines]
    color_config = folder / 'color_calibration.yaml'
    color_config.write_text('\n'.join(lines) + '\n')
    return fit.output, color_config


def build_node_assets(folder: Path, database: Path) -> NodeAssets:
    """The node assets in ``folder``, with the pose database saved at ``database`` (the
    ``node_assets`` fixture of conftest.py builds them once per session)."""
    from colorglove_ros.core.segmentation.calibration_fit import MIN_FRAMES

    # the fewest frames a fit takes, a 5-bit LUT and 2000 pixels per class: a short fit
    calibration, color_config = synthetic_color_config(folder, MIN_FRAMES, bits=5,
                                                       max_per_class=2000)
    return NodeAssets(color_config, calibration, database)


# ------------------------------------------------------------------------------ frames
def glove_frame(seed: int, out_of_frame: bool = False):
    """A rendered 640x480 'test' frame of the gloved hand
    (``core.synthetic.frames.SyntheticFrame``)."""
    from colorglove_ros.core.synthetic import frames as synth
    from colorglove_ros.core.synthetic.conditions import sample_conditions

    rng = np.random.default_rng(seed)
    camera = synth.default_camera()
    q = synth.sample_pose(rng, camera, out_of_frame_prob=1.0 if out_of_frame else 0.0)
    return synth.render_frame(q, camera, rng, sample_conditions(rng, 'test'))


def hand_far_out_of_frame_rgb(seed: int) -> np.ndarray:
    """A frame whose hand centre projects 60 px left of the image (most of it outside)."""
    from colorglove_ros.core.synthetic import frames as synth
    from colorglove_ros.core.synthetic.conditions import sample_conditions

    rng = np.random.default_rng(seed)
    camera = synth.default_camera()
    from colorglove_ros.core.hand.glove import default_hand

    q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0).copy()
    centre = default_hand()[0].keypoints(q).mean(axis=0)     # camera frame, metres
    u = camera.fx * centre[0] / centre[2] + camera.cx
    q[0] += (-60.0 - u) * centre[2] / camera.fx
    return synth.render_frame(q, camera, rng, sample_conditions(rng, 'test')).image_rgb


def background_rgb(seed: int = 3) -> np.ndarray:
    """A 640x480 procedural desk background with no hand, as sRGB uint8."""
    from colorglove_ros.core.colorimetry import linear_to_srgb
    from colorglove_ros.core.synthetic.backgrounds import make_background

    linear = make_background('desk', seed, 640, 480)
    return (np.clip(linear_to_srgb(linear, np.float32), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def header(sec: int, nanosec: int = 0, frame_id: str = 'camera_optical_frame'):
    """A ``std_msgs/Header``."""
    from builtin_interfaces.msg import Time
    from std_msgs.msg import Header

    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


# ------------------------------------------------------------------------------ messages
# what lookup_node is given in these tests: 40 candidates re-ranked, the 10 nearest blended
LOOKUP_CANDIDATES = 40
LOOKUP_BLEND = 10


def observation_msg(segmenter, rgb: np.ndarray, stamp_header):
    """What ``segmenter`` (``core.segmentation.segmenter.Segmenter``) makes of ``rgb``, as
    segmentation_node sends it (a ``HandObservation``); the hand must be found."""
    from colorglove_ros.ros.conversions import observation_to_msg

    observation = segmenter.process(rgb)
    assert observation.hand_found, observation.status
    return observation_to_msg(observation, stamp_header)


def node_lookup(assets: NodeAssets):
    """The ``PoseLookup`` of the nodes' database, with lookup_node's settings here."""
    from colorglove_ros.core.lookup.database import load_database
    from colorglove_ros.core.lookup.search import PoseLookup

    return PoseLookup(load_database(assets.database), LOOKUP_CANDIDATES, LOOKUP_BLEND)


def candidates_msg(lookup, observation, camera):
    """What ``lookup`` makes of the ``HandObservation`` seen by ``camera`` (without the
    per-finger blend of its blobs), as a ``HandPoseCandidates`` message."""
    from colorglove_ros.ros.conversions import (
        candidates_to_msg,
        crop_from_observation_msg,
        tiny_labels_from_observation_msg,
    )

    result = lookup.lookup(tiny_labels_from_observation_msg(observation),
                           crop_from_observation_msg(observation), camera)
    return candidates_to_msg(observation, result, lookup_time_ms=1.0)


# ------------------------------------------------------------------------------ harness
class Harness:
    """Nodes under test plus a probe node in one context, spun by one executor."""

    def __init__(self, context: rclpy.Context, nodes: list[Node]) -> None:
        self.context = context
        self.nodes = nodes
        self.probe = rclpy.create_node('test_probe', context=context)
        self.executor = SingleThreadedExecutor(context=context)
        for node in [*nodes, self.probe]:
            self.executor.add_node(node)

    def publisher(self, msg_type, topic: str, qos: QoSProfile = RELIABLE):
        """A probe publisher, returned once a subscriber has matched (or after 10 s)."""
        pub = self.probe.create_publisher(msg_type, topic, qos)
        self.spin_until(lambda: pub.get_subscription_count() > 0, 10.0)
        return pub

    def collect(self, msg_type, topic: str, qos: QoSProfile = RELIABLE) -> list:
        """A list that fills with every message received on ``topic``."""
        received: list = []
        self.probe.create_subscription(msg_type, topic, received.append, qos)
        return received

    def spin_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Spin until ``predicate()`` holds; False on timeout."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def exchange(self, pub, msg, received: list, timeout: float = 20.0):
        """Publish ``msg`` and return the next message that arrives in ``received``."""
        count = len(received)
        pub.publish(msg)
        assert self.spin_until(lambda: len(received) > count, timeout), \
            f'no output within {timeout} s'
        return received[count]

    def settle(self, seconds: float) -> None:
        """Spin for ``seconds`` (lets late messages arrive)."""
        self.spin_until(lambda: False, seconds)


@contextlib.contextmanager
def running(*factories: Callable[[rclpy.Context], Node]) -> Iterator[Harness]:
    """Build nodes with ``factory(context)`` in a fresh context; always shut down."""
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes: list[Node] = []
    harness = None
    try:
        for factory in factories:
            nodes.append(factory(context))
        harness = Harness(context, nodes)
        yield harness
    finally:
        if harness is not None:
            harness.executor.shutdown(timeout_sec=1.0)
            harness.probe.destroy_node()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def params(**values) -> list[Parameter]:
    """``parameter_overrides`` from keyword arguments."""
    return [Parameter(name, value=value) for name, value in values.items()]


# The pipeline node factories below default to use_camera_info false (camera 0 of
# config/calibration.yaml): the tests send images and messages without a CameraInfo, except
# those of CameraInfo itself (test/ros/nodes/test_camera_info_nodes.py), which set it true.
def segmentation_node(assets: NodeAssets, **overrides) -> Callable[[rclpy.Context], Node]:
    """A factory of segmentation_node with the assets' colour calibration (and the
    parameters ``overrides``)."""
    from colorglove_ros.ros.nodes.segmentation_node import SegmentationNode

    overrides.setdefault('use_camera_info', False)
    return lambda ctx: SegmentationNode(context=ctx, parameter_overrides=params(
        color_calibration_file=str(assets.color_config), **overrides))


def lookup_node(assets: NodeAssets, **overrides) -> Callable[[rclpy.Context], Node]:
    """A factory of lookup_node with the assets' database (settings of :func:`node_lookup`)
    and the parameters ``overrides``."""
    from colorglove_ros.ros.nodes.lookup_node import LookupNode

    overrides.setdefault('use_camera_info', False)
    return lambda ctx: LookupNode(context=ctx, parameter_overrides=params(
        database_path=str(assets.database), num_candidates=LOOKUP_CANDIDATES,
        num_neighbors=LOOKUP_BLEND, **overrides))


# The small test databases match rendered frames only loosely (their nearest image is rarely a
# close match, and the fit rarely shows the glove where it is), so the evidence gates (weak
# evidence, poor fit, missing glove) are off in the node tests that track with them; the gates
# themselves are tested in test/core/test_pipeline.py and by test_ik_node_refuses_weak_evidence.
SMALL_DATABASE_GATES = {'min_explained_blob_share': 0.0, 'max_missing_glove_share': 1.0,
                        'max_weak_match_residual_px': 1000.0}


def ik_node(database: Path, **overrides) -> Callable[[rclpy.Context], Node]:
    """A factory of ik_node (with the glove and hand of pose database ``database``) with the
    parameters ``overrides``."""
    from colorglove_ros.ros.nodes.ik_node import IKNode

    overrides.setdefault('use_camera_info', False)
    for name, value in SMALL_DATABASE_GATES.items():
        overrides.setdefault(name, value)
    return lambda ctx: IKNode(context=ctx, parameter_overrides=params(
        database_path=str(database), **overrides))


# ------------------------------------------------------------------------------ processes
def executable(name: str) -> str:
    """The console script ``name`` of this venv (falls back to PATH)."""
    path = BIN_DIR / name
    return str(path) if path.is_file() else name


def node_command(name: str, parameters: dict[str, str]) -> list[str]:
    """The command line of a node's console script with ``-p`` parameters."""
    command = [executable(name), '--ros-args']
    for key, value in parameters.items():
        command += ['-p', f'{key}:={value}']
    return command


def start_node_process(name: str, parameters: dict[str, str], env: dict[str, str]
                       ) -> subprocess.Popen:
    """Start a node's console script; stdout and stderr merged, text mode."""
    return subprocess.Popen(node_command(name, parameters), env=env, cwd=REPO_DIR,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def write_params_file(path: Path, values: dict[str, object]) -> Path:
    """A ROS 2 parameter file applying ``values`` to every node."""
    import yaml

    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': values}}))
    return path


def assert_run_tracked(run, figures: dict, frames: int, min_tracked: float = 0.9) -> None:
    """A four-node pipeline run (``ros.pipeline_run.PipelineRun``) finished, segmented every
    one of its ``frames`` camera frames with a known camera model (none answered 'camera:
    waiting for CameraInfo', as a frame played ahead of its CameraInfo is) and tracked at least
    ``min_tracked`` of them with ground truth (``figures``: its ``pipeline_run.summarize``)."""
    assert not run.timed_out
    assert run.segmented == frames, f'segmentation_node missed frames: {run.missed_frames()}'
    assert not run.camera_refusals, run.camera_refusals
    assert figures['tracked_fraction'] >= min_tracked, figures
    assert figures['frames_with_truth'] >= min_tracked * frames


#: How long a paced test feed waits for a frame's answer before resending it: long enough
#: for a frame slowed by a loaded machine (or by compiling on its first call), since a frame
#: resent and then overtaken by the next one in an image queue of depth 1 is never segmented.
TEST_PACE_TIMEOUT_S = 10.0


def paced_bag_feed(bag: Path):
    """The tests' paced feed of ``bag`` (``ros.pipeline_run.bag_feed``): each frame played
    after the previous one's answer, waiting up to :data:`TEST_PACE_TIMEOUT_S`."""
    from colorglove_ros.ros.pipeline_run import bag_feed

    return bag_feed(bag, paced=True, pace_timeout_s=TEST_PACE_TIMEOUT_S)
