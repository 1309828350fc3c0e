"""The YAML launcher: parsing, command lines, and starting/stopping real processes."""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import TEST_DIR

from colorglove_ros.launcher import Launcher, LaunchError, load_launch_file, node_command


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
        time.sleep(1.0)
        assert all(p.poll() is None for p in launcher.processes)
    finally:
        started = time.monotonic()
        launcher.stop()
    assert all(p.poll() is not None for p in launcher.processes)
    assert time.monotonic() - started < 10.0, 'nodes needed more than SIGINT to stop'


def test_watch_returns_when_a_node_exits(tmp_path: Path) -> None:
    launcher = Launcher(load_launch_file(_write(tmp_path, f"""
nodes:
  - executable: {sys.executable}
    arguments: [-c, 'import sys; sys.exit(3)']
""")))
    launcher.start()
    assert launcher.watch(threading.Event()) == 3
    launcher.stop()
