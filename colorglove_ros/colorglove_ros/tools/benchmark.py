"""Speed of the tracker on a 640x480 synthetic bag with the configured (default 100,000-entry)
database, in one run: the in-process time per stage and per frame (``ros.stage_profile``: the
node classes' callbacks with message conversion, median and p95; an uncounted warm-up pass,
then :data:`IN_PROCESS_PASSES` passes through fresh nodes, judged on the median of the passes'
per-frame medians, their range printed: one pass's median moves with the machine's moment),
then the graph over
DDS with the bag played at 30 Hz and at 60 Hz (JointStates per second and latency p50/p95 from
the camera stamp, taken by a lean subscriber in its own process; the bag is restamped at
publish time; and each process's CPU time per offered frame, which the machine's other load
disturbs less than the wall-clock figures) and two cameras at 30 Hz. The four-process graph
always; with ``--single-process`` also every node in one process
(``colorglove_single_process``). Before every pass and after the last, the machine's own speed
on fixed workloads (``core.evaluation.machine_speed``; each pass's row carries the one taken
just before it), so each figure can be read with the machine's state."""
from __future__ import annotations

import argparse
import itertools
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.evaluation.machine_speed import (
    MachineSpeed,
    machine_speed_after,
    machine_speed_before,
    measure_machine_speed,
)
from colorglove_ros.core.evaluation.metrics import latency_summary_ms
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.bags import write_synthetic_bag
from colorglove_ros.ros.latency_probe import ProbeRecord
from colorglove_ros.ros.launcher import NodeSpec
from colorglove_ros.ros.pipeline_run import (
    STAGE_OUTPUTS,
    bag_feed,
    pipeline_parameters,
    prepare_assets,
    run_pipeline,
    summarize,
)
from colorglove_ros.tools._cli import add_pipeline_arguments, run_tool, tool_parser

__all__ = ['TARGETS', 'BAG_RATE_HZ', 'IN_PROCESS_PASSES', 'STEREO_CALIBRATION', 'ensure_bag',
           'check_targets', 'isolate_domain', 'probe_failure_notes', 'stage_latency_figures',
           'main']

BAG_RATE_HZ = 30.0     # the bags' own frame rate; offered rates are multiples of it
# counted in-process passes (after the warm-up): the frame target judges their median
IN_PROCESS_PASSES = 3
STEREO_CALIBRATION = 'config/calibration_stereo.yaml'

# name: (figure, comparison, bound), issue 19
TARGETS = {
    'in one process: segmentation + lookup + IK median <= 8 ms': ('frame_p50_ms', '<=', 8.0),
    '60 Hz offered: >= 57 JointStates/s': ('dds_60hz_rate_hz', '>=', 57.0),
    '60 Hz offered: latency p95 <= 33 ms': ('dds_60hz_latency_p95_ms', '<=', 33.0),
    '30 Hz offered: latency p95 <= 20 ms': ('dds_30hz_latency_p95_ms', '<=', 20.0),
    'two cameras, 30 Hz: >= 29 JointStates/s': ('dds_2cam_30hz_rate_hz', '>=', 29.0),
    'two cameras, 30 Hz: latency p95 <= 35 ms': ('dds_2cam_30hz_latency_p95_ms', '<=', 35.0),
}


def isolate_domain(domain: int | None) -> int:
    """Run this process and the graph it starts on ROS domain ``domain``, else the
    environment's ``ROS_DOMAIN_ID``, else one of its own (200 + pid % 32) rather than the
    default domain, where another graph on the machine (someone's demo) would feed the latency
    probe and take these frames."""
    if domain is None and os.environ.get('ROS_DOMAIN_ID'):
        return int(os.environ['ROS_DOMAIN_ID'])
    chosen = 200 + os.getpid() % 32 if domain is None else int(domain)
    os.environ['ROS_DOMAIN_ID'] = str(chosen)
    return chosen


def ensure_bag(seed: int, frames: int, calibration: str | None = None) -> Path:
    """The benchmark bag for (seed, frames), written once under data/bags/; with
    ``calibration`` (a camera rig) every camera's view."""
    cameras = (default_camera(),) if calibration is None else \
        tuple(load_calibration(resolve_path(calibration)).cameras)
    suffix = '' if len(cameras) == 1 else f'_{len(cameras)}cams'
    bag = resolve_path('data') / 'bags' / f'benchmark_seed{seed}_{frames}{suffix}'
    if not (bag / 'metadata.yaml').is_file():
        print(f'[benchmark] writing {bag} ({frames} frames, once)', flush=True)
        write_synthetic_bag(bag, cameras, seed=seed, num_frames=frames, split='test')
    return bag


def check_targets(figures: dict[str, float], notes: dict[str, str] | None = None
                  ) -> list[dict[str, object]]:
    """One row per target whose figure was measured: value, threshold, margin, PASS/FAIL,
    and the ``notes`` given for its figure (e.g. :func:`probe_failure_notes`)."""
    notes = notes or {}
    return [{**target_row(name, figures[key], bound, op),
             **({'note': notes[key]} if key in notes else {})}
            for name, (key, op, bound) in TARGETS.items() if key in figures]


def probe_failure_notes(runs: list[dict[str, Any]]) -> dict[str, str]:
    """For each DDS target figure (``dds_..._rate_hz``, ``..._latency_p95_ms``) with a pass
    whose latency probe failed (its row's ``probe_error``): how many of its passes, and the
    first reason. Such a pass counts as one that got no JointState."""
    failed: dict[str, list[str]] = {}
    passes: dict[str, int] = {}
    for row in runs:
        if row['graph'] != 'separate processes':
            continue
        key = _dds_key(row)
        passes[key] = passes.get(key, 0) + 1
        if row.get('probe_error'):
            failed.setdefault(key, []).append(row['probe_error'])
    notes = {}
    for key, reasons in failed.items():
        note = (f'latency probe failed in {len(reasons)} of {passes[key]} passes (counted as no '
                f'JointState): {reasons[0]}')
        notes[f'{key}_rate_hz'] = notes[f'{key}_latency_p95_ms'] = note
    return notes


def _dds_key(row: dict[str, Any]) -> str:
    """The target figures' prefix of a DDS row: ``dds_30hz``, ``dds_2cam_30hz``, ..."""
    return f'dds_{"2cam_" if row["cameras"] == 2 else ""}{row["offered_hz"]:g}hz'


def in_process(bag: Path, parameters: dict[str, dict], frames: int, profile: bool,
               passes: int = IN_PROCESS_PASSES, warm_up: bool = True) -> dict[str, Any]:
    """The in-process pass (``ros.stage_profile``) on the bag's first ``frames``, ``passes``
    times, each through fresh nodes (the same work each time), after a warm-up pass that is
    not counted (``warm_up``). ``stages``: the stage rows, every figure the median over the
    passes (:func:`~colorglove_ros.ros.stage_profile.passes_summary`: the frame's
    ``node_p50_ms``, the target's figure, is the median of the passes' per-frame medians);
    ``passes``: one row per pass; ``warm_up``: the warm-up's frame row (None without);
    ``times``: the last pass's :class:`~colorglove_ros.ros.stage_profile.StageTimes`."""
    from colorglove_ros.ros.stage_profile import (
        frames_of_bag,
        passes_summary,
        profile_stages,
        stage_summary,
    )

    chosen = frames_of_bag(bag, frames)
    warm = stage_summary(profile_stages(chosen, parameters))[-1] if warm_up else None
    runs, speeds = [], []
    for _ in range(passes):
        speeds.append(measure_machine_speed())
        runs.append(profile_stages(chosen, parameters, profile=profile))
    stages, per_pass = passes_summary(runs)
    for row, speed in zip(per_pass, speeds, strict=True):
        row.update(_machine_columns(speed))
    return {'stages': stages, 'passes': per_pass, 'warm_up': warm, 'times': runs[-1]}


def _machine_columns(speed: MachineSpeed) -> dict[str, float]:
    """The machine's speed just before a pass, as that pass's row's columns."""
    return {'machine_python_loop_ms': speed.python_loop_ms,
            'machine_numpy_sort_ms': speed.numpy_sort_ms}


def _second_camera(parameters: dict[str, dict]
                   ) -> tuple[list[NodeSpec], dict[str, str], dict[str, int]]:
    """Parameters, node and input topic of a second camera's segmentation_node (camera 1 of
    :data:`STEREO_CALIBRATION`, in its namespace as a bag carries it), and the subscribers
    the bag player waits for on that camera's topics (its image: segmentation2; its
    CameraInfo: segmentation2 and ik_node)."""
    second = load_calibration(resolve_path(STEREO_CALIBRATION)).cameras[1].name
    parameters['segmentation2'] = dict(parameters['segmentation'])
    parameters['ik'] = {**parameters['ik'], 'calibration_file': STEREO_CALIBRATION,
                        'extra_observation_topics': [f'/{second}/hand/observation']}
    image, info = f'/{second}/camera/image_raw', f'/{second}/camera/camera_info'
    spec = NodeSpec('segmentation_node', 'segmentation2', remappings={
        'camera/image_raw': image, 'hand/observation': f'/{second}/hand/observation',
        'camera/camera_info': info,
        'hand/segmentation_debug': f'/{second}/hand/segmentation_debug'})
    return [spec], {image: 'segmentation2'}, {image: 1, info: 2}


def dds_pass(bag: Path, parameters: dict[str, dict], frames: int, offered_hz: float,
             single_process: bool, two_cameras: bool = False, stage_latency: bool = False
             ) -> dict[str, Any] | None:
    """One run of the graph over DDS with the bag offered at ``offered_hz``: a row of the
    figures, None if it timed out. With ``stage_latency`` the latency probe also records the
    stages' outputs (:data:`STAGE_OUTPUTS`) and the row gives their latency from the camera
    stamp too (:func:`stage_latency_figures`)."""
    parameters = {name: dict(values) for name, values in parameters.items()}
    extra_nodes, extra_inputs, waits = (_second_camera(parameters) if two_cameras
                                        else ([], {}, {}))
    graph = 'single process' if single_process else 'separate processes'
    print(f'[benchmark] {graph}, {2 if two_cameras else 1} camera(s): bag offered at '
          f'{offered_hz:g} Hz', flush=True)
    run = run_pipeline(parameters, expected_frames=frames,
                       feed=bag_feed(bag, rate=offered_hz / BAG_RATE_HZ, waits=waits),
                       timeout_s=120.0 + frames / 5.0, extra_nodes=extra_nodes,
                       extra_inputs=extra_inputs, single_process=single_process,
                       stage_topics=STAGE_OUTPUTS if stage_latency else ())
    if run.timed_out:
        print('[benchmark] pass timed out', flush=True)
        return None
    if run.probe_error:
        print(f'[benchmark] {run.probe_error}: this pass has no latency figures', flush=True)
    figures = summarize(run, default_hand()[0])
    received = len(run.probe.stamp_ns) if run.probe is not None else 0
    return {'graph': graph, 'cameras': 2 if two_cameras else 1, 'offered_hz': offered_hz,
            # frames the monitor counted as offered (one CameraInfo each), of the bag's
            'frames_offered': figures['frames_seen_by_monitor'],
            # JointStates the lean probe received per second of the offered sequence
            'joint_states_per_s': received * offered_hz / frames,
            # ... and per second between its first and last arrival
            'arrival_rate_hz': figures['output_rate_hz'],
            'tracked_fraction': figures['tracked_fraction'],
            'latency_p50_ms': figures['latency_p50_ms'],
            'latency_p95_ms': figures['latency_p95_ms'],
            'segmentation_ms': figures['segmentation_compute_mean_ms'],
            'lookup_ms': figures['lookup_compute_mean_ms'],
            'ik_ms': figures['ik_compute_mean_ms'],
            'fingertip_rel_wrist_mm': figures.get('fingertip_rel_wrist_mm', float('nan')),
            # CPU time per offered frame of each process while the bag played (ms): the node
            # processes, the benchmark's own monitor, its latency probe and the bag player
            # (with its start-up)
            **{key.replace('_per_frame', ''): value for key, value in figures.items()
               if key.startswith('cpu_ms_per_frame_')},
            **(stage_latency_figures(run.probe) if stage_latency and run.probe is not None
               else {}),
            **({'probe_error': run.probe_error} if run.probe_error else {})}


def stage_latency_figures(record: ProbeRecord) -> dict[str, float]:
    """Arrival at the latency probe minus the camera stamp, p50 and p95 (ms), of each stage
    output of :data:`STAGE_OUTPUTS` the probe recorded: ``observation_latency_p50_ms``, ...,
    ``pose_candidates_latency_p95_ms`` (NaN for a stage with no message)."""
    figures = {}
    for index, (topic, _) in enumerate(STAGE_OUTPUTS):
        name = topic.rsplit('/', 1)[-1]
        summary = latency_summary_ms(record.stage_latencies_s(index))
        figures[f'{name}_latency_p50_ms'] = summary['p50']
        figures[f'{name}_latency_p95_ms'] = summary['p95']
    return figures


def _target_figures(stages: list[dict[str, Any]], runs: list[dict[str, Any]]
                    ) -> dict[str, float]:
    """The figures :data:`TARGETS` judges: the four-process graph's runs (the median over
    the repeats of a pass) and the frame row."""
    figures = {f'{row["stage"]}_p50_ms': row['node_p50_ms'] for row in stages}
    repeats: dict[str, list[float]] = {}
    for row in runs:
        if row['graph'] != 'separate processes':
            continue
        key = _dds_key(row)
        repeats.setdefault(f'{key}_rate_hz', []).append(row['joint_states_per_s'])
        # a pass that got no JointState has no latency: the worst, not NaN, in the median
        p95 = row['latency_p95_ms']
        repeats.setdefault(f'{key}_latency_p95_ms', []).append(
            float('inf') if np.isnan(p95) else p95)
    figures.update({key: float(np.median(values)) for key, values in repeats.items()})
    return figures


def main(argv: list[str] | None = None) -> int:
    """``colorglove_benchmark [--frames N] [--single-process] [--json PATH]``."""
    parser = tool_parser(__doc__.splitlines()[0])
    add_pipeline_arguments(parser, frames=300, seed=2, sequence='synthetic bag')
    parser.add_argument('--rates', type=float, nargs='+', default=[30.0, 60.0],
                        help='offered camera rates of the DDS passes, Hz (default 30 60)')
    parser.add_argument('--in-process-frames', type=int, default=150,
                        help='frames of the in-process pass (0 skips it)')
    parser.add_argument('--in-process-passes', type=int, default=IN_PROCESS_PASSES,
                        help='counted in-process passes over those frames, each through fresh '
                             'nodes; the target judges the median of their per-frame medians '
                             f'(default {IN_PROCESS_PASSES})')
    parser.add_argument('--no-warm-up', dest='warm_up', action='store_false',
                        help='no uncounted warm-up pass before the in-process passes')
    parser.add_argument('--profile', action='store_true',
                        help='also print each stage\'s cProfile (cumulative time) of the '
                             'in-process passes (the last one\'s)')
    parser.add_argument('--no-dds', action='store_true', help='the in-process pass only')
    parser.add_argument('--no-two-cameras', action='store_true',
                        help='skip the two-camera pass')
    parser.add_argument('--repeats', type=int, default=1,
                        help='run every DDS pass this many times (in turn); the targets judge '
                             'the median over the repeats')
    parser.add_argument('--single-process', action='store_true',
                        help='also run every DDS pass with all nodes in one process')
    parser.add_argument('--domain-id', type=int,
                        help='ROS domain of the measured graph (default: $ROS_DOMAIN_ID, else '
                             'one of its own)')
    parser.add_argument('--overlay', action='store_true',
                        help='ik_node also draws and publishes the overlay image (it then '
                             'receives every camera image); off by default, as in '
                             'config/nodes.yaml')
    parser.add_argument('--stage-latency', action='store_true',
                        help='the latency probe also takes the observation and candidates '
                             '(serialized, their stamps only) and every DDS row gives their '
                             'latency from the camera stamp: where a frame\'s latency goes '
                             'stage by stage (the probe then works a little more)')
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error('--repeats must be at least 1')
    if args.in_process_passes < 1:
        parser.error('--in-process-passes must be at least 1')
    return run_tool('colorglove_benchmark', lambda: _benchmark(args))


def _benchmark(args: argparse.Namespace) -> int:
    """The benchmark itself (SIGTERM and the package's errors handled by run_tool)."""
    print(f'[benchmark] ROS domain {isolate_domain(args.domain_id)}', flush=True)
    database = prepare_assets(args.database)  # a bad config or database: run_tool's error
    bag = ensure_bag(args.seed, args.frames)
    parameters = pipeline_parameters(database, args.seed, args.frames, BAG_RATE_HZ)
    del parameters['camera']
    parameters['ik']['publish_overlay'] = args.overlay
    report: dict[str, Any] = {'bag': bag.name, 'database': database.name}
    speeds = machine_speed_before()
    stages: list[dict[str, Any]] = []
    if args.in_process_frames > 0:
        print(f'[benchmark] in process: {args.in_process_frames} frames, '
              f'{"a warm-up pass (not counted), then " if args.warm_up else ""}'
              f'{args.in_process_passes} pass(es), each through fresh nodes', flush=True)
        result = in_process(bag, parameters, args.in_process_frames, args.profile,
                            args.in_process_passes, args.warm_up)
        stages, times, per_pass = result['stages'], result['times'], result['passes']
        frame_p50 = [row['frame_p50_ms'] for row in per_pass]
        report['in_process'] = stages
        report['in_process_tracked'] = min(row['tracked'] for row in per_pass)
        report['in_process_passes'] = per_pass
        report['in_process_frame_p50_range_ms'] = [min(frame_p50), max(frame_p50)]
        report['in_process_warm_up'] = result['warm_up']
        print_table(per_pass, title='in process, each pass (per-frame medians, ms; machine_*: the '
                                    'fixed workloads just before the pass)')
        warm = result['warm_up']
        print(f'[benchmark] frame p50 over {len(per_pass)} pass(es): median '
              f'{np.median(frame_p50):.2f} ms, range {min(frame_p50):.2f}-{max(frame_p50):.2f}'
              + (f' (warm-up pass, not counted: {warm["node_p50_ms"]:.2f})' if warm else ''),
              flush=True)
        print_table(stages, title=f'in process, {len(times.tracked)} frames '
                                  f'({report["in_process_tracked"]} tracked), the median over '
                                  f'{len(per_pass)} pass(es): node = input deserialisation + '
                                  'callback; compute = the stage\'s own timing')
        if args.profile:
            from colorglove_ros.ros.stage_profile import profile_text
            for name, stats in times.profiles.items():
                print(f'--- cProfile: {name}\n{profile_text(stats)}')
    runs: list[dict[str, Any]] = []
    if not args.no_dds:
        graphs = [False, True] if args.single_process else [False]
        stereo = None if args.no_two_cameras else ensure_bag(args.seed, args.frames,
                                                              STEREO_CALIBRATION)
        for single in graphs:
            passes = [(bag, rate, False) for rate in args.rates]
            if stereo is not None:
                passes.append((stereo, BAG_RATE_HZ, True))
            for repeat, (which, rate, two) in itertools.product(range(1, args.repeats + 1),
                                                                 passes):
                speed = measure_machine_speed()
                row = dds_pass(which, parameters, args.frames, rate, single, two,
                               args.stage_latency)
                if row is None:
                    return 1
                row['repeat'] = repeat
                row.update(_machine_columns(speed))
                runs.append(row)
        report['dds'] = runs
        print_table(runs, title='over DDS (latency: lean subscriber, JointState arrival minus '
                                'camera stamp; machine_*: the fixed workloads just before the '
                                'pass)')
    report['machine_speed'] = machine_speed_after(speeds)
    targets = check_targets(_target_figures(stages, runs), probe_failure_notes(runs))
    report['targets'] = targets
    print_table(targets, title='issue 19 targets (measured on this machine)')
    if args.json:
        write_json(args.json, report)
    # a pass without its latency probe measured nothing: the run failed, its rows say why
    return 1 if any(row.get('probe_error') for row in runs) else 0


if __name__ == '__main__':
    sys.exit(main())
