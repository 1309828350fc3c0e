"""The YAML launcher: parsing, command lines, and starting/stopping real processes."""
from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest
import rclpy
from colorglove_msgs.msg import HandObservation
from geometry_msgs.msg import PolygonStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from repo_paths import CONFIG_DIR, PKG_DIR, TEST_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.lookup.database import STANDARD_BUILD
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.ros.bags import camera_topics
from colorglove_ros.ros.launcher import (
    Launcher,
    LaunchError,
    NodeSpec,
    load_launch_file,
    node_command,
    process_cpu_seconds,
)
from colorglove_ros.ros.nodes import ik_node, lookup_node, segmentation_node
from colorglove_ros.ros.nodes.camera_node import CameraNode
from colorglove_ros.ros.nodes.common import CROP_PREDICTION_TOPIC, StartupError
from colorglove_ros.ros.nodes.hand_description_node import HandDescriptionNode
from colorglove_ros.ros.nodes.ik_node import IKNode

MONO_LAUNCH = CONFIG_DIR / 'pipeline.launch.yaml'
STEREO_LAUNCH = CONFIG_DIR / 'pipeline_stereo.launch.yaml'
STEREO_CALIBRATION = CONFIG_DIR / 'calibration_stereo.yaml'
NODE_CLASSES = {'camera_node': CameraNode, 'segmentation_node': segmentation_node.SegmentationNode,
                'lookup_node': lookup_node.LookupNode, 'ik_node': IKNode,
                'hand_description_node': HandDescriptionNode}
#: the parameters in which a node of the two-camera graph may differ from the one-camera one
STEREO_PARAMETERS = {'calibration_file', 'extra_observation_topics', 'camera_index'}


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / 'test.launch.yaml'
    path.write_text(text)
    return path


def test_command_line_carries_name_parameters_and_remappings(tmp_path: Path) -> None:
    (tmp_path / 'params.yaml').write_text('/**:\n  ros__parameters: {rate: 5.0}\n')
    specs = load_launch_file(_write(tmp_path, """
nodes:
  - executable: python3
    name: cam
    parameters: params.yaml
    remappings: {image_raw: /camera/image_raw}
    arguments: [-c, pass]
"""))
    command = node_command(specs[0])
    assert command[1:] == ['-c', 'pass', '--ros-args', '-r', '__node:=cam', '--params-file',
                           str(tmp_path / 'params.yaml'), '-r', 'image_raw:=/camera/image_raw']


@pytest.mark.parametrize('text, message', [
    ('nodes: []', 'non-empty list'),
    ('nodes: [{name: x}]', 'no "executable"'),
    ('nodes: [{executable: no_such_program_here}]', 'not found on PATH'),
    ('nodes: [{executable: python3, parameters: missing.yaml}]', 'parameter file not found'),
    ('nodes: [unclosed', 'not valid YAML'),
])
def test_bad_launch_files_raise(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(LaunchError, match=message):
        Launcher(load_launch_file(_write(tmp_path, text)))


def test_missing_launch_file(tmp_path: Path) -> None:
    with pytest.raises(LaunchError, match='not found'):
        load_launch_file(tmp_path / 'nope.yaml')


def test_starts_processes_and_stops_them_cleanly(tmp_path: Path, isolated_ros_domain) -> None:
    publisher = TEST_DIR / 'dds_publisher.py'
    launcher = Launcher(load_launch_file(_write(tmp_path, f"""
nodes:
  - executable: {sys.executable}
    name: first
    arguments: [{publisher}, observation, /launch_test_a, '60']
  - executable: {sys.executable}
    name: second
    arguments: [{publisher}, candidates, /launch_test_b, '60']
""")), sigint_grace_s=10.0)
    launcher.start()
    try:
        # SIGINT only once both nodes are up: one sent while a child is still inside
        # rclpy.init (its handler installed, no context yet) is lost, and the launcher rightly
        # escalates after the grace period, which is not what this test measures
        _wait_for_publishers(['/launch_test_a', '/launch_test_b'], timeout_s=30.0)
        assert all(p.poll() is None for p in launcher.processes)
    finally:
        started = time.monotonic()
        launcher.stop()
    assert all(p.poll() is not None for p in launcher.processes)
    assert time.monotonic() - started < 10.0, 'nodes needed more than SIGINT to stop'


def _wait_for_publishers(topics: list[str], timeout_s: float) -> None:
    """Wait until each of ``topics`` has a publisher in the ROS graph."""
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('publisher_watch', context=context)
        deadline = time.monotonic() + timeout_s
        while any(node.count_publishers(t) < 1 for t in topics):
            assert time.monotonic() < deadline, f'no publisher on one of {topics}'
            time.sleep(0.1)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_watch_returns_when_a_node_exits(tmp_path: Path) -> None:
    launcher = Launcher(load_launch_file(_write(tmp_path, f"""
nodes:
  - executable: {sys.executable}
    arguments: [-c, 'import sys; sys.exit(3)']
""")))
    launcher.start()
    assert launcher.watch(threading.Event()) == 3
    launcher.stop()


def test_process_cpu_seconds_is_the_process_cpu_time() -> None:
    ended = time.process_time() + 0.3
    while time.process_time() < ended:    # burn CPU in this process
        pass
    # user + system time of every thread, as time.process_time counts it (to a clock tick)
    assert process_cpu_seconds(os.getpid()) == pytest.approx(time.process_time(), abs=0.05)


def test_cpu_seconds_of_the_running_nodes(tmp_path: Path) -> None:
    launcher = Launcher(load_launch_file(_write(tmp_path, f"""
nodes:
  - executable: {sys.executable}
    name: busy
    arguments: [-c, "import time\\nwhile time.process_time() < 0.6: pass\\ntime.sleep(60)"]
  - executable: {sys.executable}
    name: idle
    arguments: [-c, 'import time; time.sleep(60)']
  - executable: {sys.executable}
    name: ended
    arguments: [-c, 'pass']
""")))
    launcher.start()
    try:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and launcher.cpu_seconds().get('busy', 0.0) < 0.5:
            time.sleep(0.1)
        used = launcher.cpu_seconds()
    finally:
        launcher.stop()
    assert set(used) == {'busy', 'idle'}       # the process that ended is left out
    assert used['busy'] >= 0.5
    assert used['idle'] < used['busy']


class _NoLookup:
    """Stands in for ``PoseLookup``: the launch test needs no pose database."""

    db = ()

    def __init__(self, *args) -> None:
        pass


@contextlib.contextmanager
def _launched(spec: NodeSpec) -> Iterator[Node]:
    """The node of ``spec``, built in this process with the command-line arguments (name,
    namespace, parameter files, ``-p``, remappings) the launcher would start it with."""
    context = rclpy.Context()
    rclpy.init(args=node_command(replace(spec, executable=sys.executable)), context=context)
    node = None
    try:
        node = NODE_CLASSES[spec.executable](context=context)
        yield node
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def _graph(path: Path, stack: contextlib.ExitStack) -> dict[str, Node]:
    """The nodes of a launch file (no camera_node) by fully qualified name."""
    nodes = [stack.enter_context(_launched(spec)) for spec in load_launch_file(path)
             if spec.executable != 'camera_node']
    return {node.get_fully_qualified_name(): node for node in nodes}


def _parameters(node: Node) -> dict[str, object]:
    return {name: p.value for name, p in node.get_parameters_by_prefix('').items()}


def _topics(endpoints, msg_type) -> list[str]:
    return [e.topic_name for e in endpoints if e.msg_type is msg_type]


def test_stereo_launch_file_runs_the_two_camera_graph(monkeypatch: pytest.MonkeyPatch,
                                                      isolated_ros_domain) -> None:
    """config/pipeline_stereo.launch.yaml: one segmentation_node per camera of the stereo
    calibration, the second reading the topics its bag view is played on and publishing where
    ik_node listens for camera 2; lookup and IK on the stereo calibration; otherwise every
    node's parameters are those of the one-camera pipeline.launch.yaml (nodes.yaml)."""
    # no colour calibration on a fresh clone: a segmenter with the default settings stands in
    monkeypatch.setattr(segmentation_node, 'load_segmenter',
                        lambda config: GloveSegmenter(calibration=None))
    # no pose database on a fresh clone: the lookup's and the IK's view of it stand in
    monkeypatch.setattr(lookup_node, 'load_database',
                        lambda path: SimpleNamespace(build=STANDARD_BUILD))
    monkeypatch.setattr(ik_node, 'read_database_build', lambda path: STANDARD_BUILD)
    monkeypatch.setattr(lookup_node, 'PoseLookup', _NoLookup)
    # nor its files to read into the page cache
    monkeypatch.setattr(lookup_node, 'start_reading_into_page_cache',
                        lambda path, database=None: None)
    rig = load_calibration(STEREO_CALIBRATION).cameras
    assert len(rig) == 2
    with contextlib.ExitStack() as stack:
        mono, stereo = _graph(MONO_LAUNCH, stack), _graph(STEREO_LAUNCH, stack)
        extra = f'/{rig[1].name}{mono["/segmentation"].get_fully_qualified_name()}'
        assert set(stereo) == set(mono) | {extra}
        assert 'camera_node' not in {s.executable for s in load_launch_file(STEREO_LAUNCH)}
        for name, node in stereo.items():
            expected = _parameters(mono[name if name != extra else '/segmentation'])
            got = _parameters(node)
            assert {k for k in got if got[k] != expected[k]} <= STEREO_PARAMETERS, name
        for name in ('/lookup', '/ik'):
            calibration = Path(stereo[name].get_parameter('calibration_file').value)
            assert (PKG_DIR / calibration).resolve() == STEREO_CALIBRATION, name
        ik = stereo['/ik']
        extra_topics = ik.get_parameter('extra_observation_topics').value
        ik_inputs = _topics(ik.subscriptions, HandObservation)
        assert ik_inputs == extra_topics                # one per extra camera, in rig order
        # each extra camera's intrinsics: ik_node reads the CameraInfo its segmentation reads
        assert {camera_topics(camera, index)[1] for index, camera in enumerate(rig)} <= {
            sub.topic_name for sub in ik.subscriptions}
        assert stereo[extra].get_parameter('camera_index').value == 1
        for index, seg in enumerate((stereo['/segmentation'], stereo[extra])):
            # input: the image and CameraInfo topics colorglove_make_bag writes for this camera
            # (crop predictions only while prediction_margin > 0, off here); the predictions'
            # topic in its namespace is ik_node's (camera 0's) for camera 0
            assert sorted(s.topic_name for s in seg.subscriptions) == sorted(
                camera_topics(rig[index], index))
            predictions = [seg.resolve_topic_name(CROP_PREDICTION_TOPIC)]
            assert (predictions == _topics(ik.publishers, PolygonStamped)) == (index == 0)
            output = _topics(seg.publishers, HandObservation)
            assert len(output) == 1
            if index == 0:
                assert output == _topics(stereo['/lookup'].subscriptions, HandObservation)
            else:
                assert output == [ik_inputs[index - 1]]


def test_synthetic_camera_renders_camera_zero_only(isolated_ros_domain) -> None:
    """Why pipeline_stereo.launch.yaml starts no camera_node (its input is a bag)."""
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(StartupError, match='camera 0 only'):
            CameraNode(context=context, parameter_overrides=[
                Parameter('calibration_file', value=str(STEREO_CALIBRATION)),
                Parameter('camera_index', value=1)])
    finally:
        rclpy.try_shutdown(context=context)


def test_overrides_follow_the_parameter_files(tmp_path: Path) -> None:
    """``overrides`` are passed as -p after --params-file, so they win over the files; values
    are written as YAML (JSON) so a string stays a string."""
    params = tmp_path / 'p.yaml'
    params.write_text('x:\n  ros__parameters:\n    rate_hz: 30.0\n')
    launch = _write(tmp_path, f"""
nodes:
  - executable: {sys.executable}
    name: x
    parameters: {params}
    overrides: {{rate_hz: 15.0, frame: 'true', topics: /a}}
""")
    command = node_command(load_launch_file(launch)[0])
    assert command.index('--params-file') < command.index('-p')
    pairs = [command[i + 1] for i, arg in enumerate(command) if arg == '-p']
    assert pairs == ['rate_hz:=15.0', 'frame:="true"', 'topics:="/a"']
    for bad in ('[a]', '{x: null}', '{x: {y: 1}}', '{x: .inf}', '{x: [[1]]}'):
        with pytest.raises(LaunchError, match='overrides'):
            load_launch_file(_write(tmp_path, f'nodes:\n  - executable: {sys.executable}\n'
                                              f'    overrides: {bad}\n'))


def test_node_parameter_file_applies_under_any_namespace(isolated_ros_domain) -> None:
    """nodes.yaml is keyed /**/NAME, so a node pushed into a namespace (a second camera, a
    second hand) still reads its section instead of silently running on defaults."""
    import yaml

    sections = yaml.safe_load((CONFIG_DIR / 'nodes.yaml').read_text())
    assert sections and all(key.startswith('/**/') for key in sections), list(sections)
    context = rclpy.Context()
    rclpy.init(context=context, args=['--ros-args', '-r', '__ns:=/camera2', '--params-file',
                                      str(CONFIG_DIR / 'nodes.yaml')])
    try:
        node = rclpy.create_node('lookup', context=context,
                                 automatically_declare_parameters_from_overrides=True)
        assert node.get_fully_qualified_name() == '/camera2/lookup'
        assert node.get_parameter('num_candidates').value == sections['/**/lookup'][
            'ros__parameters']['num_candidates']
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
