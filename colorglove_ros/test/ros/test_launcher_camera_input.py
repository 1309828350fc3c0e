"""colorglove_launch with your own camera driver: ``--no-camera``, ``--image-topic``,
``--camera-info-topic`` (``ros.launcher.with_camera_input``)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.ros import launcher
from colorglove_ros.ros.launcher import (
    CAMERA_IMAGE_TOPIC,
    CAMERA_INFO_TOPIC,
    NodeSpec,
    load_launch_file,
    node_command,
    with_camera_input,
)


def _remaps(command: list[str]) -> list[str]:
    return [command[i + 1] for i, arg in enumerate(command) if arg == '-r']


def test_pipeline_with_own_camera_driver() -> None:
    specs = load_launch_file(CONFIG_DIR / 'pipeline.launch.yaml')
    assert 'camera_node' in [s.executable for s in specs]
    assert 'hand_description_node' in [s.executable for s in specs]
    adapted = with_camera_input(specs, start_camera=False, image_topic='/drv/image_raw',
                                camera_info_topic='/drv/camera_info')
    assert [s.executable for s in adapted] == [s.executable for s in specs
                                               if s.executable != 'camera_node']
    for spec in adapted:
        remaps = _remaps(node_command(spec))
        assert f'{CAMERA_IMAGE_TOPIC}:=/drv/image_raw' in remaps
        assert f'{CAMERA_INFO_TOPIC}:=/drv/camera_info' in remaps
    assert all(s.remappings == {} for s in specs)           # the loaded specs are unchanged


def test_defaults_change_nothing() -> None:
    specs = load_launch_file(CONFIG_DIR / 'pipeline.launch.yaml')
    assert with_camera_input(specs) == specs


def test_options_win_over_the_file_and_keep_its_other_remappings() -> None:
    spec = NodeSpec(executable=sys.executable, remappings={'__ns': '/cam2',
                                                           CAMERA_IMAGE_TOPIC: '/old'})
    (adapted,) = with_camera_input([spec], image_topic='/new')
    assert adapted.remappings == {'__ns': '/cam2', CAMERA_IMAGE_TOPIC: '/new'}


def test_main_refuses_a_launch_file_left_empty(tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / 'camera_only.launch.yaml'
    path.write_text('nodes:\n  - executable: camera_node\n')
    assert launcher.main([str(path), '--no-camera']) == 2
    assert 'no node left to start' in capsys.readouterr().err
