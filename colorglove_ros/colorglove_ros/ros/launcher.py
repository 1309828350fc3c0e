"""Start a set of nodes as separate processes from one YAML file and stop them cleanly.

``ros2 launch`` is not installable from PyPI, so this is the launcher on pip-only
machines. The YAML (see ``config/pipeline.launch.yaml``)::

    nodes:
      - executable: camera_node          # console script / ros2 run executable name
        name: camera                     # optional node name (__node remap)
        parameters: [config/camera.yaml] # optional parameter files (relative to the YAML)
        remappings: {image_raw: /camera/image_raw}
        overrides: {rate_hz: 15.0}       # optional parameters set after the files (win)
        arguments: []                    # optional extra command-line arguments

``--no-camera`` leaves out the package's ``camera_node`` (images come from your own camera
driver), and ``--image-topic`` / ``--camera-info-topic`` remap every node's camera input
(``camera/image_raw``, ``camera/camera_info``) to the driver's topics, like the native launch
file's ``start_camera``, ``image_topic`` and ``camera_info_topic`` arguments.

On Ctrl-C or SIGTERM every node gets SIGINT, then SIGTERM, then SIGKILL after grace
periods. If one node exits, the others are stopped too, unless it has ``respawn: true`` and did
not fail at start-up (exit code 1): then it is started again.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from colorglove_ros import signal_exit
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.yaml_io import load_yaml_mapping

__all__ = ['LaunchError', 'NodeSpec', 'load_launch_file', 'node_command', 'Launcher',
           'process_cpu_seconds',
           'use_fastdds_profile', 'with_camera_input', 'CAMERA_NODE_EXECUTABLE',
           'CAMERA_IMAGE_TOPIC', 'CAMERA_INFO_TOPIC', 'FASTDDS_PROFILE_VARIABLE', 'main']

FASTDDS_PROFILE_VARIABLE = 'FASTRTPS_DEFAULT_PROFILES_FILE'
CAMERA_NODE_EXECUTABLE = 'camera_node'
"""The package's own camera: left out when images come from the user's camera driver."""
CAMERA_IMAGE_TOPIC = 'camera/image_raw'
"""The camera image topic the nodes publish and subscribe to (relative: follows a namespace)."""
CAMERA_INFO_TOPIC = 'camera/camera_info'
"""The camera's ``CameraInfo`` topic (relative)."""
# Exit code of a node that cannot start (ros/nodes/common.py run_node): never respawned, as a bad
# configuration does not fix itself.
STARTUP_FAILURE_CODE = 1


def use_fastdds_profile() -> str:
    """Point Fast DDS at ``config/fastdds_profile.xml`` (large shared-memory segments for
    images) for this process and its children, unless the user set a profile already.
    Returns the profile in effect."""
    from colorglove_ros.paths import share_dir

    if not os.environ.get(FASTDDS_PROFILE_VARIABLE):
        os.environ[FASTDDS_PROFILE_VARIABLE] = str(share_dir() / 'config' / 'fastdds_profile.xml')
    return os.environ[FASTDDS_PROFILE_VARIABLE]


class LaunchError(ColorGloveError):
    """A launch file is missing or malformed, or an executable cannot be found."""


@dataclass
class NodeSpec:
    """One process to start."""

    executable: str
    name: str = ''
    parameters: list[Path] = field(default_factory=list)
    remappings: dict[str, str] = field(default_factory=dict)
    arguments: list[str] = field(default_factory=list)
    respawn: bool = False
    overrides: dict[str, object] = field(default_factory=dict)


def _parameter_value(value: object) -> bool:
    """Whether ``value`` is a ROS parameter value: a bool, finite number, string, or a
    flat list of one of those."""
    if isinstance(value, list):
        return all(isinstance(v, (bool, int, float, str)) and _parameter_value(v)
                   for v in value)
    if isinstance(value, float):
        return value == value and abs(value) != float('inf')
    return isinstance(value, (bool, int, str))


def load_launch_file(path: str | Path) -> list[NodeSpec]:
    """Parse a launch YAML into node specs; parameter paths resolve relative to it."""
    path = Path(path)
    data = load_yaml_mapping(path, LaunchError, 'launch file')
    if not isinstance(data.get('nodes'), list) or not data['nodes']:
        raise LaunchError(f'launch file {path} needs a non-empty list under "nodes"')
    specs = []
    for index, entry in enumerate(data['nodes']):
        if not isinstance(entry, dict) or 'executable' not in entry:
            raise LaunchError(f'{path}: node {index} has no "executable"')
        params = entry.get('parameters', [])
        params = [params] if isinstance(params, str) else params
        overrides = entry.get('overrides') or {}
        if not isinstance(overrides, dict) or not all(
                _parameter_value(v) for v in overrides.values()):
            raise LaunchError(f'{path}: node {index}: "overrides" must map parameter names '
                              'to numbers, booleans, strings or flat lists of them')
        specs.append(NodeSpec(
            executable=str(entry['executable']),
            name=str(entry.get('name', '')),
            parameters=[(path.parent / p).resolve() for p in params],
            remappings={str(k): str(v) for k, v in (entry.get('remappings') or {}).items()},
            arguments=[str(a) for a in entry.get('arguments', [])],
            respawn=bool(entry.get('respawn', False)),
            overrides={str(k): v for k, v in overrides.items()},
        ))
    return specs


def with_camera_input(specs: list[NodeSpec], *, start_camera: bool = True,
                      image_topic: str = '', camera_info_topic: str = '') -> list[NodeSpec]:
    """``specs`` without the package's ``camera_node`` unless ``start_camera``, and with every
    node's ``camera/image_raw`` and ``camera/camera_info`` remapped to ``image_topic`` and
    ``camera_info_topic`` where given (these win over the launch file's own remappings)."""
    remaps = {source: target for source, target in ((CAMERA_IMAGE_TOPIC, image_topic),
                                                   (CAMERA_INFO_TOPIC, camera_info_topic))
              if target}
    return [replace(spec, remappings={**spec.remappings, **remaps}) for spec in specs
            if start_camera or spec.executable != CAMERA_NODE_EXECUTABLE]


def node_command(spec: NodeSpec) -> list[str]:
    """The command line that starts ``spec`` (console script + ``--ros-args``)."""
    executable = shutil.which(spec.executable)
    if executable is None:
        raise LaunchError(f'executable {spec.executable!r} not found on PATH '
                          '(is the colorglove_ros venv active?)')
    command = [executable, *spec.arguments, '--ros-args']
    if spec.name:
        command += ['-r', f'__node:={spec.name}']
    for param_file in spec.parameters:
        if not param_file.is_file():
            raise LaunchError(f'parameter file not found: {param_file}')
        command += ['--params-file', str(param_file)]
    for name, value in spec.overrides.items():
        # after the files, so they win; JSON is valid YAML, which is how -p values are read
        command += ['-p', f'{name}:={json.dumps(value)}']
    for source, target in spec.remappings.items():
        command += ['-r', f'{source}:={target}']
    return command


def process_cpu_seconds(pid: int) -> float:
    """CPU time (user + system, seconds) process ``pid`` has used so far, from
    ``/proc/<pid>/stat`` (Linux); ``OSError`` if there is no such process."""
    with open(f'/proc/{pid}/stat', encoding='ascii', errors='replace') as stat:
        text = stat.read()
    # fields after the command name, which is in parentheses and may hold spaces and ')'
    fields = text[text.rindex(')') + 2:].split()
    # utime and stime are fields 14 and 15 of proc(5), 12 and 13 after the name
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class Launcher:
    """Runs node processes, prefixes their output, and stops them in order."""

    def __init__(self, specs: list[NodeSpec], sigint_grace_s: float = 5.0,
                 sigterm_grace_s: float = 3.0) -> None:
        self.specs = specs
        self.commands = [node_command(spec) for spec in specs]
        self.processes: list[subprocess.Popen | None] = [None] * len(specs)
        self.sigint_grace_s = sigint_grace_s
        self.sigterm_grace_s = sigterm_grace_s

    def _label(self, index: int) -> str:
        return self.specs[index].name or self.specs[index].executable

    def _start(self, index: int) -> None:
        with signal_exit.deferred():       # a started process is always recorded
            process = subprocess.Popen(self.commands[index], stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, text=True, errors='replace',
                                       bufsize=1,
                                       start_new_session=True)
            self.processes[index] = process
        label = self._label(index)
        threading.Thread(target=_relay, args=(process, label), daemon=True).start()
        print(f'[launch] started {label} (pid {process.pid})', flush=True)

    def start(self) -> None:
        """Start every node (with the Fast DDS profile of :func:`use_fastdds_profile`), after
        removing shared-memory segments left by killed participants."""
        use_fastdds_profile()
        _clean_shared_memory()
        for index in range(len(self.specs)):
            self._start(index)

    def cpu_seconds(self) -> dict[str, float]:
        """CPU time (seconds) each running node process has used so far, by node label
        (:func:`process_cpu_seconds`); processes that ended are left out."""
        used = {}
        for index, process in enumerate(self.processes):
            if process is not None and process.poll() is None:
                try:
                    used[self._label(index)] = process_cpu_seconds(process.pid)
                except OSError:     # ended between the poll and the read
                    pass
        return used

    def watch(self, stop_event: threading.Event) -> int:
        """Wait until ``stop_event`` is set or a non-respawning node exits; return its code."""
        while not stop_event.wait(0.2):
            for index, process in enumerate(self.processes):
                code = process.poll() if process else None
                if code is None:
                    continue
                label = self._label(index)
                if code == STARTUP_FAILURE_CODE:
                    print(f'[launch] {label} cannot start (exit code {code}); stopping the rest',
                          flush=True)
                    return code
                if self.specs[index].respawn:
                    print(f'[launch] {label} exited with {code}; respawning', flush=True)
                    self._start(index)
                    _clean_shared_memory()     # the dead process's segments (once stale)
                else:
                    print(f'[launch] {label} exited with {code}; stopping the rest', flush=True)
                    return code
        return 0

    def stop(self) -> None:
        """SIGINT every running node, then SIGTERM, then SIGKILL after grace periods."""
        for sig, grace in ((signal.SIGINT, self.sigint_grace_s),
                           (signal.SIGTERM, self.sigterm_grace_s), (signal.SIGKILL, 5.0)):
            running = [p for p in self.processes if p is not None and p.poll() is None]
            if not running:
                return
            for process in running:
                process.send_signal(sig)
            deadline = time.monotonic() + grace
            for process in running:
                try:
                    process.wait(timeout=max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    pass


def _clean_shared_memory() -> None:
    from colorglove_ros.ros.shm_cleanup import clean_stale_fastdds_segments

    removed, freed = clean_stale_fastdds_segments()
    if removed:
        print(f'[launch] removed {removed} stale Fast DDS shared-memory file(s), '
              f'{freed / 2**20:.0f} MiB', flush=True)


def _relay(process: subprocess.Popen, label: str) -> None:
    for line in process.stdout:
        sys.stdout.write(f'[{label}] {line}')
        sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point: ``colorglove_launch LAUNCH_YAML [--duration S] [--no-camera]
    [--image-topic T] [--camera-info-topic T]``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('launch_file', help='YAML listing the nodes to start')
    parser.add_argument('--duration', type=float, default=0.0,
                        help='stop everything after this many seconds (0 = run until Ctrl-C)')
    parser.add_argument('--no-camera', action='store_true',
                        help=f'do not start {CAMERA_NODE_EXECUTABLE} (images come from your '
                             'own camera driver)')
    parser.add_argument('--image-topic', default='',
                        help=f'remap every node\'s {CAMERA_IMAGE_TOPIC} to this topic')
    parser.add_argument('--camera-info-topic', default='',
                        help=f'remap every node\'s {CAMERA_INFO_TOPIC} to this topic')
    args = parser.parse_args(argv)
    try:
        specs = with_camera_input(load_launch_file(args.launch_file),
                                  start_camera=not args.no_camera, image_topic=args.image_topic,
                                  camera_info_topic=args.camera_info_topic)
        if not specs:
            raise LaunchError(f'{args.launch_file}: no node left to start')
        launcher = Launcher(specs)
    except LaunchError as exc:
        print(f'colorglove_launch: {exc}', file=sys.stderr)
        return 2
    stop_event = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop_event.set())
    timer = threading.Timer(args.duration, stop_event.set)
    timer.daemon = True
    if args.duration > 0:
        timer.start()
    try:
        launcher.start()
        code = launcher.watch(stop_event)
    finally:
        timer.cancel()
        launcher.stop()
        print('[launch] all nodes stopped', flush=True)
    return code


if __name__ == '__main__':
    sys.exit(main())
