"""Restart time of a killed node: the four tracker nodes as separate processes over DDS with the
camera looping a synthetic sequence; each of segmentation_node, lookup_node and ik_node is
killed with SIGKILL --kills times while the others keep running, and started again at once (as
a launch file's respawn does, without its delay). Per kill: seconds from the new process's start
to its first output (hand/observation, hand/pose_candidates, hand/joint_states), taken by a
subscriber in this process. Prints a table per kill and per node; --json writes the same."""
from __future__ import annotations

import os
import signal
import tempfile
import time
from pathlib import Path

import numpy as np

from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.tools._cli import add_pipeline_arguments, run_tool, tool_parser

__all__ = ['main']

VICTIMS = {'segmentation': 'hand/observation', 'lookup': 'hand/pose_candidates',
           'ik': 'hand/joint_states'}
"""Node name -> the topic whose first message after a restart counts as its first output."""


class _OutputTimes:
    """Arrival times (time.monotonic) of every message on the victims' output topics."""

    def __init__(self) -> None:
        from colorglove_msgs.msg import HandObservation, HandPoseCandidates
        from sensor_msgs.msg import JointState

        from colorglove_ros.ros.background_node import BackgroundNode

        self.arrivals: dict[str, list[float]] = {name: [] for name in VICTIMS}
        self.listener = BackgroundNode('restart_probe')
        types = {'segmentation': HandObservation, 'lookup': HandPoseCandidates,
                 'ik': JointState}
        for name, topic in VICTIMS.items():
            self.listener.node.create_subscription(
                types[name], '/' + topic,
                lambda _msg, n=name: self.arrivals[n].append(time.monotonic()), 10)
        self.listener.start()

    def first_after(self, name: str, since: float, timeout_s: float) -> float:
        """Seconds from ``since`` to the first ``name`` output after it (NaN on timeout)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            later = [t for t in list(self.arrivals[name]) if t > since]
            if later:
                return later[0] - since
            time.sleep(0.005)
        return float('nan')

    def close(self) -> None:
        """Stop listening."""
        self.listener.close()


def _measure(args) -> int:
    from colorglove_ros.ros.pipeline_run import looping_pipeline

    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as folder:
        launcher, database = looping_pipeline(args.database, args.seed, args.frames, args.rate,
                                              Path(folder))
        outputs = _OutputTimes()
        try:                     # started inside the try: a SIGTERM must stop what runs
            launcher.start()
            if np.isnan(outputs.first_after('ik', 0.0, args.startup_timeout)):
                print(f'[restart] no JointState within {args.startup_timeout:g} s of start-up',
                      flush=True)
                return 1
            time.sleep(args.settle)
            labels = [spec.name for spec in launcher.specs]
            for kill in range(args.kills):
                for name in VICTIMS:
                    index = labels.index(name)
                    os.kill(launcher.processes[index].pid, signal.SIGKILL)
                    launcher.processes[index].wait()
                    killed = time.monotonic()
                    launcher._start(index)
                    started = time.monotonic()
                    first = outputs.first_after(name, started, args.timeout)
                    rows.append({'kill': kill + 1, 'node': name,
                                 'respawn_s': started - killed,
                                 'start_to_first_output_s': first,
                                 'downstream_ok': not np.isnan(
                                     outputs.first_after('ik', started + first, args.timeout))
                                 if not np.isnan(first) else False})
                    time.sleep(args.settle)
        finally:
            launcher.stop()
            outputs.close()
    print_table(rows, title='restart after SIGKILL (start of the new process -> its first output)')
    summary = []
    for name in VICTIMS:
        times = np.array([r['start_to_first_output_s'] for r in rows if r['node'] == name])
        summary.append({'node': name, 'kills': len(times),
                        'median_s': float(np.nanmedian(times)) if len(times) else np.nan,
                        'max_s': float(np.max(times)) if len(times) else np.nan,
                        'no_output': int(np.isnan(times).sum())})
    print_table(summary, title='restart summary')
    if args.json:
        write_json(args.json, {'kills': rows, 'summary': summary,
                               'settings': {'rate_hz': args.rate, 'kills': args.kills,
                                            'database': str(database)}})
    return 0 if all(r['no_output'] == 0 for r in summary) else 1


def main(argv: list[str] | None = None) -> int:
    """``colorglove_restart [--kills N] [--rate HZ] [--json PATH]``."""
    parser = tool_parser(__doc__.split('\n\n')[0])
    parser.add_argument('--kills', type=int, default=3, help='kills per node')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate offered, Hz')
    parser.add_argument('--settle', type=float, default=3.0,
                        help='seconds of normal running between kills')
    parser.add_argument('--timeout', type=float, default=30.0,
                        help='longest wait for a restarted node\'s first output, seconds')
    parser.add_argument('--startup-timeout', type=float, default=180.0,
                        help='longest wait for the first JointState, seconds')
    add_pipeline_arguments(parser, frames=300, seed=1, sequence='looping synthetic sequence')
    args = parser.parse_args(argv)
    return run_tool('colorglove_restart', lambda: _measure(args))
