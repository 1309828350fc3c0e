"""Speed of two_hands_node over DDS: a synthetic bag of a left and a right glove (each hand on
its side of a 640x480 image) played at the offered rates, restamped at publish time, into
``two_hands_node`` in its own process; a lean subscriber in another process records each
hand's JointStates (``/hand/left/joint_states``, ``/hand/right/joint_states``). Per hand and
rate: JointStates per second of the offered sequence, the share of frames answered with a pose,
and latency p50/p95 (arrival minus the camera frame's header stamp).

In parts of a sequence a hand is out of view or hidden by the other arm, and gets no pose
however fast the node is. So each frame's visibility is known (both hands fully visible, as the
two-hand evaluation decides it: ``core.evaluation.two_hand_frames``; kept beside the bag as
``<bag>_visibility.json``), the player logs the stamp it gave each frame, and the rate target is
judged on the frames with both hands fully visible: the share of them answered with a pose,
times the offered rate. The frames of the first ``--startup-s`` seconds are the node's start-up
(its first frame pays one-time costs, and frames arriving meanwhile are dropped by its one-deep
queue): the missed ones are counted apart, and the target is judged on the frames after them;
the share over all frames is printed beside."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from contextlib import closing
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.evaluation.machine_speed import machine_speed_after, machine_speed_before
from colorglove_ros.core.evaluation.metrics import latency_summary_ms
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.evaluation.two_hand_frames import RATE_TARGET_PER_HAND_HZ
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

__all__ = ['VISIBILITY_FORMAT', 'hand_rows', 'two_hand_bag', 'frame_visibility',
           'node_parameters', 'main']

IMAGE_TOPICS = [TOPIC_IMAGE, TOPIC_CAMERA_INFO]
#: Version of the ``<bag>_visibility.json`` layout.
VISIBILITY_FORMAT = 1


def joint_states_topic(hand: str) -> str:
    """The absolute JointState topic of ``hand`` as two_hands_node publishes it."""
    from colorglove_ros.ros.nodes.two_hands_node import hand_topic

    return '/' + hand_topic(hand, 'joint_states')


def two_hand_bag(path: Path, seed: int, frames: int) -> Path:
    """The bag at ``path``, written once (with its visibility file): ``frames`` frames of
    two-hand sequence ``seed`` (test conditions) at :data:`BAG_RATE_HZ`; its ground-truth
    topics are those of the first hand of :data:`HANDS` (the right)."""
    if (path / 'metadata.yaml').is_file():
        held = bag_image_count(path)
        if held != frames:
            raise BagError(f'{path} holds {held} frames, not {frames}: give --frames {held} '
                           'or another --bag')
        return path
    from colorglove_ros.core.synthetic.frames import default_camera

    print(f'[benchmark_two_hands] writing {path} ({frames} frames, once)', flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    with SequenceBagWriter(path, default_camera(), fps=BAG_RATE_HZ) as writer:
        visible = _render_sequence(seed, frames, writer.write)
    _write_visibility(path, seed, visible)
    return path


def _render_sequence(seed: int, frames: int, write: Any = None) -> list[bool]:
    """Render two-hand sequence ``seed`` (test conditions) as the bag holds it, passing each
    frame to ``write`` if given; whether both hands are fully visible, per frame."""
    from colorglove_ros.core.evaluation.two_hand_frames import two_hand_frames
    from colorglove_ros.core.synthetic.conditions import sample_conditions
    from colorglove_ros.core.synthetic.frames import Synthesizer, default_camera
    from colorglove_ros.core.synthetic.sequences import two_hand_sequences

    camera = default_camera()
    synth = Synthesizer()
    try:
        poses = two_hand_sequences(seed, frames, BAG_RATE_HZ, camera=camera, model=synth.model)
        conditions = sample_conditions(np.random.default_rng([seed, 7]), 'test')
        visible = []
        for shot in two_hand_frames(synth, camera, poses, seed, conditions, frames):
            if write is not None:
                write(shot.frame)
            visible.append(shot.fully_visible)
    finally:
        synth.release()
    return visible


def visibility_path(bag: Path) -> Path:
    """Where the visibility of ``bag``'s frames is kept: beside the bag folder."""
    return bag.with_name(bag.name + '_visibility.json')


def _write_visibility(bag: Path, seed: int, visible: Sequence[bool]) -> None:
    write_json(visibility_path(bag), {'format': VISIBILITY_FORMAT, 'seed': seed,
                                      'frames': len(visible),
                                      'both_fully_visible': [bool(v) for v in visible]})


def frame_visibility(bag: Path, seed: int, frames: int) -> dict[int, bool]:
    """{recorded header stamp (ns): both hands fully visible} for every image of ``bag``
    (two-hand sequence ``seed``), from its visibility file, rendered and written there first
    when it is missing; a :class:`BagError` when the file is not of this bag."""
    path = visibility_path(bag)
    if not path.is_file():
        print(f'[benchmark_two_hands] writing {path} (once)', flush=True)
        _write_visibility(bag, seed, _render_sequence(seed, frames))
    try:
        held = json.loads(path.read_text())
        visible = [bool(v) for v in held['both_fully_visible']]
        fits = (held['format'], held['seed'], held['frames'], len(visible)) == (
            VISIBILITY_FORMAT, seed, frames, frames)
    except (ValueError, KeyError, TypeError) as error:
        raise BagError(f'{path}: not a visibility file ({error!r}); delete it to render it '
                       'again') from error
    if not fits:
        raise BagError(f'{path} is not of sequence {seed} x {frames} frames (format '
                       f'{VISIBILITY_FORMAT}); delete it to render it again')
    stamps = bag_image_stamps(bag)
    if len(stamps) != frames:
        raise BagError(f'{bag} holds {len(stamps)} images, not {frames}')
    return dict(zip(stamps, visible, strict=True))


def bag_image_stamps(path: Path) -> list[int]:
    """The header stamps (ns) of the bag's camera images, in order (read from the serialized
    bytes: the images are not decoded)."""
    from colorglove_ros.ros.bags import bag_messages
    from colorglove_ros.ros.image_codec import header_stamp_from_cdr

    stamps = []
    with closing(open_bag_reader(path)) as reader:
        connections = [c for c in reader.connections if c.topic == TOPIC_IMAGE]
        for _, _, raw in bag_messages(reader, connections, path):
            sec, nanosec = header_stamp_from_cdr(raw)
            stamps.append(sec * 10**9 + nanosec)
    return sorted(stamps)


def bag_image_count(path: Path) -> int:
    """How many camera images the bag at ``path`` holds."""
    with closing(open_bag_reader(path)) as reader:
        return sum(c.msgcount for c in reader.connections if c.topic == TOPIC_IMAGE)


def hand_rows(record: Any, hands: Sequence[str], frames: int, offered_hz: float,
              visible_at: dict[int, bool] | None = None,
              startup_frames: int = 0) -> list[dict[str, Any]]:
    """One row per hand from a probe record of the hands' topics, ``hands[k]`` being the
    hand of the probe's topic ``k``. ``visible_at`` ({JointState stamp: both hands fully
    visible in its frame}, every frame the player sent) adds the figures over the frames with
    both hands fully visible: over all of them, and over those after the first
    ``startup_frames`` frames sent (the node's start-up; its misses counted apart)."""
    rows = []
    for index, hand in enumerate(hands):
        own = record.of_topic(index)
        latency = latency_summary_ms(list(own.latencies_s))
        row = {'hand': hand, 'offered_hz': offered_hz, 'joint_states': len(own.stamp_ns),
               # JointStates per second of the offered sequence
               'joint_states_per_s': len(own.stamp_ns) * offered_hz / frames,
               'answered_fraction': len(own.stamp_ns) / frames}
        if visible_at is not None:
            unknown = [int(s) for s in own.stamp_ns if int(s) not in visible_at]
            if unknown:
                raise ValueError(f'{hand}: {len(unknown)} JointStates with a stamp the player '
                                 f'did not send (first {unknown[0]} ns)')
            got = {int(s) for s in own.stamp_ns}
            sent = sorted(visible_at)
            shown = [stamp for stamp in sent if visible_at[stamp]]
            startup = [stamp for stamp in sent[:startup_frames] if visible_at[stamp]]
            steady = [stamp for stamp in sent[startup_frames:] if visible_at[stamp]]
            share = _answered_share(shown, got)
            steady_share = _answered_share(steady, got)
            row.update({'frames_both_visible': len(shown),
                        'answered_when_visible': share,
                        'joint_states_per_s_when_visible': share * offered_hz,
                        'startup_frames_missed': sum(stamp not in got for stamp in startup),
                        'answered_when_visible_after_startup': steady_share,
                        # the rate the node keeps up while both hands can be tracked
                        'joint_states_per_s_when_visible_after_startup':
                            steady_share * offered_hz})
        row.update({'latency_p50_ms': latency['p50'], 'latency_p95_ms': latency['p95']})
        rows.append(row)
    return rows


def _answered_share(stamps: Sequence[int], answered: set[int]) -> float:
    """The share of ``stamps`` in ``answered`` (NaN for none)."""
    return sum(stamp in answered for stamp in stamps) / len(stamps) if stamps else float('nan')


def dds_pass(bag: Path, parameters: dict[str, Any], frames: int, offered_hz: float,
             visible: dict[int, bool], node_startup_s: float = 1.0,
             startup_s: float = 120.0) -> list[dict[str, Any]]:
    """two_hands_node with ``parameters`` fed ``bag`` at ``offered_hz``: one row per hand
    (``visible``: {recorded image stamp: both hands fully visible}; the frames of the first
    ``node_startup_s`` seconds are the node's start-up)."""
    import shutil

    from colorglove_ros.ros.latency_probe import LatencyProbe
    from colorglove_ros.ros.launcher import Launcher, NodeSpec, use_fastdds_profile
    from colorglove_ros.ros.pipeline_run import write_params
    from colorglove_ros.tools.play_bag import read_stamp_log

    player = shutil.which('colorglove_play_bag')
    if player is None:
        raise FileNotFoundError('colorglove_play_bag not on PATH (is the venv active?)')
    print(f'[benchmark_two_hands] bag offered at {offered_hz:g} Hz', flush=True)
    use_fastdds_profile()
    with tempfile.TemporaryDirectory() as folder:
        params_file = write_params({'two_hands': parameters}, Path(folder))
        stamp_log = Path(folder) / 'stamps.csv'
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
                            str(startup_s), '--linger', '1.0', '--stamp-log', str(stamp_log)],
                           check=True, stdout=subprocess.DEVNULL, timeout=timeout_s)
            record = probe.stop()
        finally:
            if record is None:
                probe.close()
            launcher.stop()
        sent = read_stamp_log(stamp_log)
    return hand_rows(record, HANDS, frames, offered_hz,
                     {published: visible[recorded] for published, recorded in sent.items()},
                     startup_frames=round(node_startup_s * offered_hz))


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
    parser.add_argument('--opencv-threads', type=int,
                        help="two_hands_node's opencv_threads parameter (default its own; -1: "
                        "OpenCV's own thread pool)")
    parser.add_argument('--startup-s', type=float, default=1.0,
                        help="seconds of frames counted as the node's start-up: its misses "
                             'are counted apart, the rate target is judged on the frames after '
                             'them (default 1; 0: every frame)')
    parser.add_argument('--domain-id', type=int,
                        help='ROS domain of the measured graph (default: $ROS_DOMAIN_ID, else '
                             'one of its own)')
    args = parser.parse_args(argv)
    return run_tool('colorglove_benchmark_two_hands', lambda: _benchmark(args))


def node_parameters(args: argparse.Namespace, database: Path) -> dict[str, Any]:
    """two_hands_node's parameters for the run: the database, and the colour config, threads
    and OpenCV threads where given (else the node's defaults)."""
    parameters: dict[str, Any] = {'database_path': str(database)}
    for name, value in (('color_calibration_file', args.color_config),
                        ('threads', args.threads), ('opencv_threads', args.opencv_threads)):
        if value is not None:
            parameters[name] = str(value) if isinstance(value, Path) else value
    return parameters


def _benchmark(args: argparse.Namespace) -> int:
    from colorglove_ros.ros.pipeline_run import prepare_assets

    print(f'[benchmark_two_hands] ROS domain {isolate_domain(args.domain_id)}', flush=True)
    database = prepare_assets(args.database)
    bag = two_hand_bag(args.bag or resolve_path('data') / 'bags' /
                       f'two_hands_seed{args.seed}_{args.frames}', args.seed, args.frames)
    visible = frame_visibility(bag, args.seed, args.frames)
    parameters = node_parameters(args, database)
    rows: list[dict[str, Any]] = []
    machine = machine_speed_before()
    started = time.monotonic()
    for rate in args.rates:
        rows.extend(dds_pass(bag, parameters, args.frames, rate, visible, args.startup_s))
    print_table(rows, title=f'two_hands_node over DDS, {args.frames} frames of two-hand '
                            f'sequence {args.seed} (latency: lean subscriber, JointState '
                            'arrival minus camera stamp)')
    targets = [target_row(f'{row["hand"]} hand, {row["offered_hz"]:g} Hz offered, frames with '
                          f'both hands fully visible after the first {args.startup_s:g} s: >= '
                          f'{RATE_TARGET_PER_HAND_HZ:g} JointStates/s',
                          row['joint_states_per_s_when_visible_after_startup'],
                          RATE_TARGET_PER_HAND_HZ, '>=')
               for row in rows if row['offered_hz'] == BAG_RATE_HZ]
    print_table(targets, title='issue 18 rate target (measured on this machine)')
    machine_speed_after(machine)
    if args.json:
        write_json(args.json, {'bag': bag.name, 'database': database.name,
                               'node_parameters': {k: v for k, v in parameters.items()
                                                   if k != 'database_path'}, 'dds': rows,
                               'startup_s': args.startup_s, 'targets': targets,
                               'machine_speed': machine, 'wall_s': time.monotonic() - started})
    return 0


if __name__ == '__main__':
    sys.exit(main())
