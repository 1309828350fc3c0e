"""Speed of two_hands_node over DDS: a synthetic bag of a left and a right glove (each hand on
its side of a 640x480 image) played at the offered rates, restamped at publish time, into
``two_hands_node`` in its own process; a lean subscriber in another process records each
hand's JointStates (``/hand/left/joint_states``, ``/hand/right/joint_states``). Per hand and
rate: JointStates per second of the offered sequence, the share of frames answered with a pose,
and latency p50/p95 (arrival minus the camera frame's header stamp)."""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from contextlib import closing
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.evaluation.metrics import latency_summary_ms
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.handedness import HANDS
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.bags import (
    TOPIC_CAMERA_INFO,
    TOPIC_IMAGE,
    BagError,
    SequenceBagWriter,
    open_bag_reader,
)
from colorglove_ros.tools._cli import add_pipeline_arguments, run_tool, tool_parser
from colorglove_ros.tools.benchmark import BAG_RATE_HZ, isolate_domain

__all__ = ['TARGET_PER_HAND_HZ', 'hand_rows', 'two_hand_bag', 'main']

TARGET_PER_HAND_HZ = 30.0      # issue 18: JointStates/s per hand with a 30 Hz camera
IMAGE_TOPICS = [TOPIC_IMAGE, TOPIC_CAMERA_INFO]


def joint_states_topic(hand: str) -> str:
    """The absolute JointState topic of ``hand`` as two_hands_node publishes it."""
    from colorglove_ros.ros.nodes.two_hands_node import hand_topic

    return '/' + hand_topic(hand, 'joint_states')


def two_hand_bag(path: Path, seed: int, frames: int) -> Path:
    """The bag at ``path``, written once: ``frames`` frames of two-hand sequence ``seed``
    (test conditions) at :data:`BAG_RATE_HZ`; its ground-truth topics are those of the first
    hand of :data:`HANDS` (the right)."""
    if (path / 'metadata.yaml').is_file():
        held = bag_image_count(path)
        if held != frames:
            raise BagError(f'{path} holds {held} frames, not {frames}: give --frames {held} '
                           'or another --bag')
        return path
    from colorglove_ros.core.synthetic.conditions import sample_conditions
    from colorglove_ros.core.synthetic.frames import Synthesizer, default_camera
    from colorglove_ros.core.synthetic.sequences import two_hand_sequences

    print(f'[benchmark_two_hands] writing {path} ({frames} frames, once)', flush=True)
    camera = default_camera()
    synth = Synthesizer()
    try:
        poses = two_hand_sequences(seed, frames, BAG_RATE_HZ, camera=camera, model=synth.model)
        conditions = sample_conditions(np.random.default_rng([seed, 7]), 'test')
        path.parent.mkdir(parents=True, exist_ok=True)
        with SequenceBagWriter(path, camera, fps=BAG_RATE_HZ) as writer:
            for i in range(frames):
                frame, _ = synth.render_hands([(poses[h][i], h) for h in HANDS],
                                              camera, np.random.default_rng([seed, i, 11]),
                                              conditions)
                writer.write(frame)
    finally:
        synth.release()
    return path


def bag_image_count(path: Path) -> int:
    """How many camera images the bag at ``path`` holds."""
    with closing(open_bag_reader(path)) as reader:
        return sum(c.msgcount for c in reader.connections if c.topic == TOPIC_IMAGE)


def hand_rows(record: Any, hands: Sequence[str], frames: int, offered_hz: float
              ) -> list[dict[str, Any]]:
    """One row per hand from a probe record of the hands' topics, ``hands[k]`` being the
    hand of the probe's topic ``k``."""
    rows = []
    for index, hand in enumerate(hands):
        own = record.of_topic(index)
        latency = latency_summary_ms(list(own.latencies_s))
        rows.append({'hand': hand, 'offered_hz': offered_hz, 'joint_states': len(own.stamp_ns),
                     # JointStates per second of the offered sequence
                     'joint_states_per_s': len(own.stamp_ns) * offered_hz / frames,
                     'answered_fraction': len(own.stamp_ns) / frames,
                     'latency_p50_ms': latency['p50'], 'latency_p95_ms': latency['p95']})
    return rows


def dds_pass(bag: Path, parameters: dict[str, Any], frames: int, offered_hz: float,
             startup_s: float = 120.0) -> list[dict[str, Any]]:
    """two_hands_node with ``parameters`` fed ``bag`` at ``offered_hz``: one row per hand."""
    import shutil

    from colorglove_ros.ros.latency_probe import LatencyProbe
    from colorglove_ros.ros.launcher import Launcher, NodeSpec, use_fastdds_profile
    from colorglove_ros.ros.pipeline_run import write_params

    player = shutil.which('colorglove_play_bag')
    if player is None:
        raise FileNotFoundError('colorglove_play_bag not on PATH (is the venv active?)')
    print(f'[benchmark_two_hands] bag offered at {offered_hz:g} Hz', flush=True)
    use_fastdds_profile()
    with tempfile.TemporaryDirectory() as folder:
        params_file = write_params({'two_hands': parameters}, Path(folder))
        launcher = Launcher([NodeSpec('two_hands_node', 'two_hands', [params_file])])
        probe = LatencyProbe(topics=[joint_states_topic(hand) for hand in HANDS])
        timeout_s = startup_s + 5.0 * frames / offered_hz + 60.0
        record = None
        try:
            probe.start()
            launcher.start()
            # the player waits for two_hands_node's image subscription (startup included)
            subprocess.run([player, str(bag), '--rate', str(offered_hz / BAG_RATE_HZ),
                            '--restamp', '--topics', *IMAGE_TOPICS, '--min-subscribers', '1',
                            '--min-info-subscribers', '0', '--wait-subscribers',
                            str(startup_s), '--linger', '1.0'],
                           check=True, stdout=subprocess.DEVNULL, timeout=timeout_s)
            record = probe.stop()
        finally:
            if record is None:
                probe.close()
            launcher.stop()
    return hand_rows(record, HANDS, frames, offered_hz)


def main(argv: list[str] | None = None) -> int:
    """``colorglove_benchmark_two_hands [--rates 30 60] [--json PATH]``."""
    parser = tool_parser(__doc__.splitlines()[0])
    add_pipeline_arguments(parser, frames=300, seed=2000, sequence='two-hand bag')
    parser.add_argument('--rates', type=float, nargs='+', default=[30.0, 60.0],
                        help='offered camera rates, Hz (default 30 60)')
    parser.add_argument('--bag', type=Path,
                        help='the two-hand bag (written there once; default '
                             'data/bags/two_hands_seed<SEED>_<FRAMES>)')
    parser.add_argument('--color-config', type=Path,
                        help='colour calibration config of the node (default its own)')
    parser.add_argument('--threads', type=int, choices=(1, 2),
                        help="two_hands_node's threads parameter (default its own)")
    parser.add_argument('--domain-id', type=int,
                        help='ROS domain of the measured graph (default: $ROS_DOMAIN_ID, else '
                             'one of its own)')
    args = parser.parse_args(argv)
    return run_tool('colorglove_benchmark_two_hands', lambda: _benchmark(args))


def _benchmark(args: argparse.Namespace) -> int:
    from colorglove_ros.ros.pipeline_run import prepare_assets

    print(f'[benchmark_two_hands] ROS domain {isolate_domain(args.domain_id)}', flush=True)
    database = prepare_assets(args.database)
    bag = two_hand_bag(args.bag or resolve_path('data') / 'bags' /
                       f'two_hands_seed{args.seed}_{args.frames}', args.seed, args.frames)
    parameters: dict[str, Any] = {'database_path': str(database)}
    if args.color_config is not None:
        parameters['color_calibration_file'] = str(args.color_config)
    if args.threads is not None:
        parameters['threads'] = args.threads
    rows: list[dict[str, Any]] = []
    started = time.monotonic()
    for rate in args.rates:
        rows.extend(dds_pass(bag, parameters, args.frames, rate))
    print_table(rows, title=f'two_hands_node over DDS, {args.frames} frames of two-hand '
                            f'sequence {args.seed} (latency: lean subscriber, JointState '
                            'arrival minus camera stamp)')
    targets = [target_row(f'{row["hand"]} hand, {row["offered_hz"]:g} Hz offered: >= '
                          f'{TARGET_PER_HAND_HZ:g} JointStates/s', row['joint_states_per_s'],
                          TARGET_PER_HAND_HZ, '>=')
               for row in rows if row['offered_hz'] == BAG_RATE_HZ]
    print_table(targets, title='issue 18 rate target (measured on this machine)')
    if args.json:
        write_json(args.json, {'bag': bag.name, 'database': database.name, 'dds': rows,
                               'targets': targets,
                               'wall_s': time.monotonic() - started})
    return 0


if __name__ == '__main__':
    sys.exit(main())
