"""Throughput and latency of the four-node pipeline: a 640x480 synthetic bag played into
segmentation_node, lookup_node and ik_node (separate processes over DDS) with the configured
(default 100,000-entry) database. Latency (JointState arrival minus the camera frame's header
stamp, taken by a lean subscriber in its own process; the bag is restamped at publish time) is
measured at the 30 Hz camera rate, with each stage's own processing time; throughput in a second
pass that offers frames faster (--throughput-rate times 30 Hz), as JointStates per second
delivered."""
from __future__ import annotations

import sys
from pathlib import Path

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.frames import default_camera
from colorglove_ros.paths import resolve_path
from colorglove_ros.ros.bags import write_synthetic_bag
from colorglove_ros.ros.pipeline_run import (
    bag_feed,
    pipeline_parameters,
    prepare_assets,
    run_pipeline,
    summarize,
)
from colorglove_ros.tools._cli import add_pipeline_arguments, tool_error, tool_parser

__all__ = ['TARGETS', 'ensure_bag', 'main']

# name: (figure, comparison, bound)
TARGETS = {
    'throughput >= 30 frames/s': ('throughput_hz', '>=', 30.0),
    'latency p95 < 60 ms': ('latency_p95_ms', '<', 60.0),
}


def ensure_bag(seed: int, frames: int) -> Path:
    """The benchmark bag for (seed, frames), written once under data/bags/."""
    bag = resolve_path('data') / 'bags' / f'benchmark_seed{seed}_{frames}'
    if not (bag / 'metadata.yaml').is_file():
        print(f'[benchmark] writing {bag} ({frames} frames, once)', flush=True)
        write_synthetic_bag(bag, (default_camera(),), seed=seed, num_frames=frames,
                            split='test')
    return bag


def check_targets(figures: dict[str, float]) -> list[dict[str, object]]:
    """One row per target: measured value, threshold, margin and PASS/FAIL."""
    return [target_row(name, figures[key], bound, op)
            for name, (key, op, bound) in TARGETS.items()]


def main(argv: list[str] | None = None) -> int:
    """``colorglove_benchmark [--frames N] [--rate R] [--json PATH]``."""
    parser = tool_parser(__doc__.splitlines()[0])
    add_pipeline_arguments(parser, frames=300, seed=2, sequence='synthetic bag')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed of the latency pass (1.0 = the 30 Hz camera rate)')
    parser.add_argument('--throughput-rate', type=float, default=2.0,
                        help='playback speed of the throughput pass (2.0 = offered at 60 Hz)')
    parser.add_argument('--overlay', action='store_true',
                        help='ik_node also draws and publishes the overlay image (it then '
                             'receives every camera image); off by default, as in '
                             'config/nodes.yaml')
    args = parser.parse_args(argv)
    try:
        database = prepare_assets(args.database)
    except ColorGloveError as exc:     # a missing or corrupt config, calibration or database
        return tool_error('colorglove_benchmark', exc)
    bag = ensure_bag(args.seed, args.frames)
    parameters = pipeline_parameters(database, args.seed, args.frames, 30.0)
    del parameters['camera']
    parameters['ik']['publish_overlay'] = args.overlay
    model = default_hand()[0]
    runs = {}
    for name, rate in (('latency', args.rate), ('throughput', args.throughput_rate)):
        print(f'[benchmark] {name} pass: bag played at {30.0 * rate:g} Hz', flush=True)
        runs[name] = run_pipeline(parameters, expected_frames=args.frames,
                                  feed=bag_feed(bag, rate=rate),
                                  timeout_s=120.0 + args.frames / 5.0)
        if runs[name].timed_out:
            print(f'[benchmark] {name} pass timed out', flush=True)
            return 1
    figures = summarize(runs['latency'], model)
    figures['playback_rate_hz'] = 30.0 * args.rate
    throughput = summarize(runs['throughput'], model)
    figures['throughput_offered_hz'] = 30.0 * args.throughput_rate
    figures['throughput_hz'] = throughput['output_rate_hz']
    figures['throughput_tracked_fraction'] = throughput['tracked_fraction']
    figures['overlay'] = float(args.overlay)
    print_table([{'figure': k, 'value': v} for k, v in figures.items()],
                title=f'pipeline benchmark: {bag.name}, {database.name}')
    targets = check_targets(figures)
    print_table(targets, title='targets (measured on this machine)')
    if args.json:
        write_json(args.json, {'figures': figures, 'targets': targets})
    return 0


if __name__ == '__main__':
    sys.exit(main())
