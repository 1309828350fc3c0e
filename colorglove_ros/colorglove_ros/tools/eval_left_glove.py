"""The left glove against the right one: the same evaluation sequences, once as rendered
(right glove) and once mirrored (left hand in the mirror-image glove: every pose and the light
mirrored, the background not), one camera, IK + smoothing.

The left hand is served by the right-hand database and tracker: its query (tiny image, crop,
blobs) is mirrored about the principal point and the tracked pose mirrored back
(core.hand.handedness). Seeds O..O+S-1 are evaluation seeds (core.evaluation.sequences); the
reported figures use O = 0, nothing was tuned for this comparison. Targets are measured, not
asserted: the left glove's fingertip error within 1 mm of the right glove's.
"""
from __future__ import annotations

import time
from typing import Any

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.sequences import (
    SequenceEvaluator,
    eval_seeds,
    make_observer,
    open_database_for_calibration,
    summarize,
)
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.handedness import HANDS
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.tracking.config import load_ik_config
from colorglove_ros.paths import data_dir
from colorglove_ros.tools._cli import sequence_tool_parser, tool_error

__all__ = ['main', 'FIGURES', 'MAX_DIFFERENCE_MM', 'compare_hands']

MODE = 'ik_smooth'
# (figure key, printed name); the first two are judged
FIGURES = (('fingertip_mm', 'fingertip_mm'), ('fingertip_rel_wrist_mm', 'fingertip_rel_wrist_mm'),
           ('joint_mae_deg', 'joint_mae_deg'), ('wrist_plane_mm', 'wrist_plane_mm'),
           ('wrist_depth_mm', 'wrist_depth_mm'), ('jitter_mm', 'jitter_mm'),
           ('tracked_fraction', 'tracked'))
JUDGED = ('fingertip_mm', 'fingertip_rel_wrist_mm')
MAX_DIFFERENCE_MM = 1.0


def compare_hands(figures: dict[str, dict[str, float]]) -> list[dict[str, Any]]:
    """The targets on the per-hand figures: ``|left - right| <= MAX_DIFFERENCE_MM`` for
    each judged fingertip figure."""
    return [target_row(f'left glove {key} within {MAX_DIFFERENCE_MM:g} mm of the right '
                       'glove (|left - right|)',
                       abs(figures['left'][key] - figures['right'][key]), MAX_DIFFERENCE_MM,
                       '<=') for key in JUDGED]


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = sequence_tool_parser(__doc__, 'evaluation sequences (seeds O..O+S-1)')
    parser.add_argument('--seed-offset', type=int, default=0, help='first sequence seed O')
    args = parser.parse_args(argv)
    from colorglove_ros.core.lookup.search import PoseLookup

    t0 = time.perf_counter()
    try:
        db_path, db, mono = open_database_for_calibration(args.database, data_dir(),
                                                          args.calibration)
        config = load_ik_config(args.ik_config)
        seeds = eval_seeds(args.sequences, args.seed_offset)
        lookup = PoseLookup(db)
        evaluators = {hand: SequenceEvaluator(
            lookup, {'1 camera': mono.cameras[:1]}, (MODE,), config,
            make_observer(args.labels, args.color_config, config.min_blob_pixels),
            fps=args.fps, hand=hand) for hand in HANDS}
    except ColorGloveError as exc:
        return tool_error('colorglove_eval_left_glove', exc)
    figures: dict[str, dict[str, float]] = {}
    for hand, evaluator in evaluators.items():
        runs = []
        for s in seeds:
            ts = time.perf_counter()
            runs.append(evaluator.run(s, args.frames)[('1 camera', MODE)])
            print(f'[eval_left_glove] {hand} glove, sequence {s}: {args.frames} frames in '
                  f'{time.perf_counter() - ts:.1f} s', flush=True)
        evaluator.close()
        figures[hand] = summarize(evaluator.model, runs)
    rows = [{'glove': hand, **{name: figures[hand].get(key, float('nan'))
                               for key, name in FIGURES}} for hand in HANDS]
    rows.append({'glove': 'left - right', **{
        name: figures['left'].get(key, float('nan')) - figures['right'].get(key, float('nan'))
        for key, name in FIGURES}})
    print_table(rows, f'Left glove (mirrored sequences) against the right glove: {len(seeds)} '
                f'sequences x {args.frames} frames (seeds {seeds[0]}..{seeds[-1]}), '
                f'labels={args.labels}, 1 camera, IK + smoothing, database {db_path} '
                f'({len(db)} entries)')
    targets = compare_hands(figures)
    print_table(targets, 'Targets (measured, not asserted)')
    settings = {'database': str(db_path), 'entries': len(db), 'seeds': seeds,
                'frames_per_sequence': args.frames, 'labels': args.labels,
                'ik_config': args.ik_config, 'calibration': args.calibration,
                'fps': args.fps, 'mode': MODE, 'wall_s': time.perf_counter() - t0}
    if args.json:
        write_json(args.json, {'settings': settings, 'rows': rows, 'targets': targets})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
