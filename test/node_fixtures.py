"""Shared helpers for the node tests: small assets built once per session, rendered frames,
an in-process node harness and a runner for node processes."""
from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
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
    build_seconds: dict[str, float]


_ASSETS: dict[str, NodeAssets] = {}


def _build_assets(folder: Path) -> NodeAssets:
    from colorglove_ros.core.lookup.database import save_database
    from colorglove_ros.core.lookup.database_build import BuildConfig, build_database
    from colorglove_ros.tools import calibrate_colors

    timings = {}
    started = time.perf_counter()
    calibration = folder / 'cal.npz'
    # 8 frames is the tool's minimum; 5-bit LUT and 2000 pixels per class keep it ~15-25 s.
    code = calibrate_colors.main(['--synthetic', '8', '--bits', '5', '--max-pixels', '2000',
                                  '--output', str(calibration),
                                  '--frames-out', str(folder / 'calibration_frames')])
    assert code == 0 and calibration.is_file(), 'calibrate_colors failed'
    timings['calibrate_colors'] = time.perf_counter() - started
    # The tool writes --output; the nodes read the file named by a colour config YAML, whose
    # relative paths resolve against the working folder, so the copy names it absolutely.
    lines = (CONFIG_DIR / 'color_calibration.yaml').read_text().splitlines()
    lines = [f'calibration_file: {calibration}' if line.startswith('calibration_file:')
             else line for line in lines]
    color_config = folder / 'color_calibration.yaml'
    color_config.write_text('\n'.join(lines) + '\n')

    started = time.perf_counter()
    db = build_database(BuildConfig(entries=96, orientations_per_config=16, collection_size=400,
                                    num_bits=32, num_pairs=200, training_images=200, batch=64))
    database = save_database(db, folder / 'db')
    timings['build_database'] = time.perf_counter() - started
    return NodeAssets(color_config, calibration, Path(database), timings)


def node_assets(tmp_path_factory: pytest.TempPathFactory) -> NodeAssets:
    """The assets, built on first use in this session (shared by every test module)."""
    key = str(tmp_path_factory.getbasetemp())
    if key not in _ASSETS:
        _ASSETS[key] = _build_assets(tmp_path_factory.mktemp('node_assets'))
    return _ASSETS[key]


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
