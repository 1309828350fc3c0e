"""The main job: render the default synthetic sequence, run the four tracker nodes as separate
processes over DDS, and report frames, rate, latency (a lean subscriber's JointState arrival
minus the camera frame's header stamp), each stage's own processing time and accuracy against
ground truth, with an overlay strip (PNG) a person can look at. Missing assets (colour
calibration, pose database) are made first, once."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.ros.pipeline_run import (
    pipeline_parameters,
    prepare_assets,
    run_pipeline,
    summarize,
)
from colorglove_ros.tools._cli import add_pipeline_arguments, run_tool, tool_parser

__all__ = ['overlay_strip', 'main']


def overlay_strip(images: list[np.ndarray], columns: int = 4, width: int = 320) -> np.ndarray:
    """Tile overlay frames into one RGB image, ``columns`` wide, each scaled to ``width``."""
    if not images:
        raise ValueError('no overlay images to tile')
    scaled = [cv2.resize(img, (width, int(img.shape[0] * width / img.shape[1])))
              for img in images]
    rows = [scaled[i:i + columns] for i in range(0, len(scaled), columns)]
    blank = np.zeros_like(scaled[0])
    return np.vstack([np.hstack(row + [blank] * (columns - len(row))) for row in rows])


def main(argv: list[str] | None = None) -> int:
    """``colorglove_demo [--frames N] [--seed S] [--json PATH]``."""
    parser = tool_parser(__doc__.splitlines()[0])
    add_pipeline_arguments(parser, frames=150, seed=1, sequence='synthetic sequence')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate, frames/s')
    parser.add_argument('--output', type=Path, default=Path('out/demo'),
                        help='folder for the overlay strip')
    args = parser.parse_args(argv)
    return run_tool('colorglove_demo', lambda: _demo(args))


def _demo(args: argparse.Namespace) -> int:
    """The demo itself (SIGTERM and the package's errors handled by run_tool)."""
    started = time.perf_counter()
    database = prepare_assets(args.database)  # a bad config or database: run_tool's error
    print(f'[demo] running camera_node (synthetic seed {args.seed}, {args.frames} frames at '
          f'{args.rate:g} Hz), segmentation_node, lookup_node, ik_node', flush=True)
    run = run_pipeline(pipeline_parameters(database, args.seed, args.frames, args.rate),
                       expected_frames=args.frames, timeout_s=120.0 + args.frames / 5.0)
    if run.timed_out:
        print(f'[demo] timed out: {run.frames} of {args.frames} frames seen, '
              f'{run.tracked} tracked', flush=True)
    if run.probe_error:
        print(f'[demo] {run.probe_error}: no latency figures', flush=True)
    figures = summarize(run, default_hand()[0])
    print_table([{'figure': key, 'value': value} for key, value in figures.items()],
                title=f'colorglove demo: {args.frames} synthetic frames, database {database}')
    args.output.mkdir(parents=True, exist_ok=True)
    if run.overlays:
        strip = args.output / 'overlay_strip.png'
        cv2.imwrite(str(strip), cv2.cvtColor(overlay_strip(run.overlays), cv2.COLOR_RGB2BGR))
        print(f'overlay strip: {strip}')
    else:
        print('no overlay images arrived (no frame was tracked)')
    if args.json:
        write_json(args.json, figures)
    print(f'demo finished in {time.perf_counter() - started:.0f} s')
    return 0 if figures['frames_tracked'] > 0 and not run.timed_out else 1


if __name__ == '__main__':
    sys.exit(main())
