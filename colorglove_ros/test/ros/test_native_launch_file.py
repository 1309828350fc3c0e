"""launch/colorglove.launch.py without ROS 2 launch installed (it is not on PyPI): its
arguments read by ``ast``, and ``generate_launch_description()`` run against small stand-ins
for ``launch``, ``launch_ros`` and ``ament_index_python`` that record what it asks for, so the
nodes, remappings, parameters and the robot description of each argument setting are checked.
"""
from __future__ import annotations

import ast
import importlib.util
import os
import sys
import types
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml
from calibration_files import calibration_with_hand_length
from repo_paths import CONFIG_DIR, PKG_DIR

from colorglove_ros.core.hand.frames import finger_joint_names, hand_root_frame
from colorglove_ros.core.hand.urdf import calibrated_hand_urdf
from colorglove_ros.ros.launcher import (
    CAMERA_IMAGE_TOPIC,
    CAMERA_INFO_TOPIC,
    FASTDDS_PROFILE_VARIABLE,
)
from colorglove_ros.ros.nodes.common import JOINT_STATES_TOPIC

LAUNCH_FILE = PKG_DIR / 'launch' / 'colorglove.launch.py'
ARGUMENTS = {'image_topic', 'camera_info_topic', 'start_camera', 'namespace', 'frame_prefix',
             'fastdds_profile', 'params_file', 'use_robot_state_publisher', 'calibration_file'}


# ------------------------------------------------------------------ ast
def _calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, 'id', getattr(node.func, 'attr', None)) == name]


def _first_string(call: ast.Call) -> str:
    assert call.args and isinstance(call.args[0], ast.Constant), ast.dump(call)
    return call.args[0].value


def test_every_argument_is_declared_once_and_used() -> None:
    tree = ast.parse(LAUNCH_FILE.read_text())
    declared = [_first_string(call) for call in _calls(tree, 'DeclareLaunchArgument')]
    used = {_first_string(call) for call in _calls(tree, 'LaunchConfiguration')}
    assert sorted(declared) == sorted(ARGUMENTS)          # each once, none missing
    assert used == set(declared)                          # each used, none undeclared
    for call in _calls(tree, 'DeclareLaunchArgument'):
        keywords = {k.arg for k in call.keywords}
        assert {'default_value', 'description'} <= keywords, _first_string(call)


# ------------------------------------------------------------------ stand-ins
class _Recorded:
    """An action or substitution of the stand-in modules: its arguments, recorded."""

    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class _Context:
    """What the launch file's functions read from a launch context."""

    def __init__(self) -> None:
        self.launch_configurations: dict[str, str] = {}


class LaunchDescription(_Recorded):
    def __init__(self, initial_entities: list) -> None:
        super().__init__(initial_entities)


class DeclareLaunchArgument(_Recorded):
    def __init__(self, name: str, *, default_value=None, description: str = '',
                 choices=None) -> None:
        super().__init__(name, default_value=default_value, description=description)


class GroupAction(_Recorded):
    def __init__(self, actions: list, *, scoped: bool = True, condition=None) -> None:
        super().__init__(actions, condition=condition)


class OpaqueFunction(_Recorded):
    def __init__(self, *, function, condition=None) -> None:
        super().__init__(function=function, condition=condition)


class SetEnvironmentVariable(_Recorded):
    def __init__(self, name, value, *, condition=None) -> None:
        super().__init__(name, value, condition=condition)


class IfCondition(_Recorded):
    def __init__(self, predicate_expression) -> None:
        super().__init__(predicate_expression)

    def evaluate(self, context: _Context) -> bool:
        value = _perform(self.args[0], context).lower()
        assert value in ('true', 'false', '1', '0'), value
        return value in ('true', '1')


class UnlessCondition(IfCondition):
    def evaluate(self, context: _Context) -> bool:
        return not super().evaluate(context)


class LaunchConfiguration(_Recorded):
    def __init__(self, variable_name: str, *, default=None) -> None:
        super().__init__(variable_name)

    def perform(self, context: _Context) -> str:
        return context.launch_configurations[self.args[0]]


class EnvironmentVariable(_Recorded):
    def __init__(self, name: str, *, default_value=None) -> None:
        super().__init__(name, default_value=default_value)

    def perform(self, context: _Context) -> str:
        return os.environ.get(self.args[0], _perform(self.kwargs['default_value'], context))


class Node(_Recorded):
    def __init__(self, *, executable, package=None, name=None, parameters=None,
                 remappings=None, output=None, respawn=False, respawn_delay=None,
                 condition=None, arguments=None, namespace=None) -> None:
        super().__init__(executable=executable, package=package, name=name,
                         parameters=parameters or [], remappings=remappings or [],
                         condition=condition)


class PushRosNamespace(_Recorded):
    def __init__(self, namespace) -> None:
        super().__init__(namespace)


def get_package_share_directory(package_name: str) -> str:
    assert package_name == 'colorglove_ros'
    return str(PKG_DIR)


def _perform(value, context: _Context):
    """A substitution's text, or each item of a list / value of a dict performed."""
    if hasattr(value, 'perform'):
        return value.perform(context)
    if isinstance(value, list | tuple):
        return type(value)(_perform(v, context) for v in value)
    if isinstance(value, dict):
        return {k: _perform(v, context) for k, v in value.items()}
    return value


STAND_INS = {
    'launch': {'LaunchDescription': LaunchDescription},
    'launch.actions': {c.__name__: c for c in (DeclareLaunchArgument, GroupAction,
                                               OpaqueFunction, SetEnvironmentVariable)},
    'launch.conditions': {'IfCondition': IfCondition, 'UnlessCondition': UnlessCondition},
    'launch.substitutions': {'LaunchConfiguration': LaunchConfiguration,
                             'EnvironmentVariable': EnvironmentVariable},
    'launch_ros': {},
    'launch_ros.actions': {'Node': Node, 'PushRosNamespace': PushRosNamespace},
    'ament_index_python': {},
    'ament_index_python.packages': {
        'get_package_share_directory': get_package_share_directory},
}


@dataclass
class Launched:
    """What the launch description starts for one setting of the arguments."""

    nodes: dict[str, dict] = field(default_factory=dict)   # by node name
    environment: dict[str, str] = field(default_factory=dict)
    namespace: str = ''


def _run(entities: list, context: _Context, launched: Launched) -> None:
    """Walk the entities in order as the launch service does (depth first)."""
    for entity in entities:
        condition = entity.kwargs.get('condition')
        if condition is not None and not condition.evaluate(context):
            continue
        if isinstance(entity, DeclareLaunchArgument):
            context.launch_configurations.setdefault(
                entity.args[0], _perform(entity.kwargs['default_value'], context))
        elif isinstance(entity, OpaqueFunction):
            _run(entity.kwargs['function'](context) or [], context, launched)
        elif isinstance(entity, GroupAction):
            _run(entity.args[0], context, launched)
        elif isinstance(entity, PushRosNamespace):
            launched.namespace = _perform(entity.args[0], context)
        elif isinstance(entity, SetEnvironmentVariable):
            launched.environment[_perform(entity.args[0], context)] = \
                _perform(entity.args[1], context)
        elif isinstance(entity, Node):
            spec = _perform(dict(entity.kwargs), context)
            assert spec['name'] not in launched.nodes
            launched.nodes[spec['name']] = spec
        else:
            raise AssertionError(f'unexpected entity {entity!r}')


@pytest.fixture
def launch(monkeypatch: pytest.MonkeyPatch):
    """``launch(**arguments)``: what the launch file starts with those launch arguments."""
    for module_name, names in STAND_INS.items():
        module = types.ModuleType(module_name)
        module.__dict__.update(names)
        monkeypatch.setitem(sys.modules, module_name, module)
    monkeypatch.delenv(FASTDDS_PROFILE_VARIABLE, raising=False)
    spec = importlib.util.spec_from_file_location('colorglove_launch_under_test', LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def run(**arguments: str) -> Launched:
        assert set(arguments) <= ARGUMENTS
        description = module.generate_launch_description()
        assert isinstance(description, LaunchDescription)
        context = _Context()
        context.launch_configurations.update(arguments)
        launched = Launched()
        _run(description.args[0], context, launched)
        return launched

    return run


TRACKERS = {'camera': 'camera_node', 'segmentation': 'segmentation_node',
            'lookup': 'lookup_node', 'ik': 'ik_node'}


def test_defaults_start_the_package_camera_and_robot_state_publisher(launch) -> None:
    launched = launch()
    assert set(launched.nodes) == {*TRACKERS, 'robot_state_publisher'}
    assert launched.namespace == ''
    assert launched.environment == {
        FASTDDS_PROFILE_VARIABLE: str(PKG_DIR / 'config' / 'fastdds_profile.xml')}
    sections = yaml.safe_load((CONFIG_DIR / 'nodes.yaml').read_text())
    for name, executable in TRACKERS.items():
        node = launched.nodes[name]
        assert (node['package'], node['executable']) == ('colorglove_ros', executable)
        assert (PKG_DIR / 'colorglove_ros' / 'ros' / 'nodes' / f'{executable}.py').is_file()
        assert f'/**/{name}' in sections                 # nodes.yaml has its section
        assert node['remappings'] == [(CAMERA_IMAGE_TOPIC, CAMERA_IMAGE_TOPIC),
                                      (CAMERA_INFO_TOPIC, CAMERA_INFO_TOPIC)]
        params_file, overrides = node['parameters']
        assert params_file == str(CONFIG_DIR / 'nodes.yaml')
        assert overrides == {'calibration_file': str(CONFIG_DIR / 'calibration.yaml'),
                             'frame_prefix': ''}
    rsp = launched.nodes['robot_state_publisher']
    assert (rsp['package'], rsp['executable']) == ('robot_state_publisher',) * 2
    assert rsp['remappings'] == [('joint_states', JOINT_STATES_TOPIC)]
    assert rsp['parameters'] == [
        {'robot_description': calibrated_hand_urdf(CONFIG_DIR / 'calibration.yaml')}]


def test_own_camera_driver_and_second_hand(launch, tmp_path: Path) -> None:
    """start_camera false, the driver's topics, a namespace and prefix, a 0.17 m hand."""
    calibration = calibration_with_hand_length(tmp_path, 0.17)
    launched = launch(start_camera='false', image_topic='/drv/color/image_raw',
                      camera_info_topic='/drv/color/camera_info', namespace='right',
                      frame_prefix='right_', calibration_file=str(calibration))
    assert set(launched.nodes) == {'segmentation', 'lookup', 'ik', 'robot_state_publisher'}
    assert launched.namespace == 'right'
    for name in ('segmentation', 'lookup', 'ik'):
        node = launched.nodes[name]
        assert node['remappings'] == [(CAMERA_IMAGE_TOPIC, '/drv/color/image_raw'),
                                      (CAMERA_INFO_TOPIC, '/drv/color/camera_info')]
        assert node['parameters'][1] == {'calibration_file': str(calibration),
                                         'frame_prefix': 'right_'}
    urdf = launched.nodes['robot_state_publisher']['parameters'][0]['robot_description']
    assert urdf == calibrated_hand_urdf(calibration, 'right_')
    root = ET.fromstring(urdf)
    assert root.find('link').get('name') == hand_root_frame('right_')
    assert set(finger_joint_names('right_')) <= {j.get('name') for j in root.iter('joint')}
    assert 'hand length 0.17 m' in urdf


def test_without_robot_state_publisher_the_description_node_runs(launch) -> None:
    launched = launch(use_robot_state_publisher='false', frame_prefix='left_')
    assert set(launched.nodes) == {*TRACKERS, 'hand_description'}
    node = launched.nodes['hand_description']
    assert node['executable'] == 'hand_description_node'
    assert (PKG_DIR / 'colorglove_ros' / 'ros' / 'nodes' / 'hand_description_node.py').is_file()
    assert node['parameters'][1]['frame_prefix'] == 'left_'


def test_fastdds_profile(launch, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    assert launch(fastdds_profile='').environment == {}
    mine = str(tmp_path / 'mine.xml')
    assert launch(fastdds_profile=mine).environment == {FASTDDS_PROFILE_VARIABLE: mine}
    monkeypatch.setenv(FASTDDS_PROFILE_VARIABLE, mine)       # the user's own profile wins
    assert launch().environment == {FASTDDS_PROFILE_VARIABLE: mine}


def test_a_bad_frame_prefix_stops_the_launch(launch) -> None:
    from colorglove_ros.core.hand.frames import FramePrefixError

    with pytest.raises(FramePrefixError):
        launch(frame_prefix='right hand')
