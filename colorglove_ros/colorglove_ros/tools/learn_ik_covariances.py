"""Learn the IK covariances R, Q, P on training sequences and save them (Wang-Popovic 5.3-5.4).

The tracker runs in 'ik' mode (IK, no temporal term) over synthetic TRAINING sequences,
seeds 100000..100000+S-1 (core.evaluation.sequences.train_seeds; eval_ik evaluates on seeds 0..S-1,
so the two sets are disjoint), with 'train' imaging conditions. The reference pose of each
frame is the 5-frame local average of the tracker's estimates, as in the paper
(--reference local_average), or the ground truth (--reference truth, a diagnostic: its P
is too small for the smoothing term). R = constraint
residuals at the reference, Q = IK prior (translation-fitted blend) minus reference,
P = previous frame about the current local average
(core.tracking.covariance_learning.learn_covariances).
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.metrics import LOCAL_WINDOW
from colorglove_ros.core.evaluation.sequences import (
    SequenceEvaluator,
    make_observer,
    open_database,
    train_seeds,
    training_sequences,
)
from colorglove_ros.core.hand.model import DOF_NAMES
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.tracking.config import (
    default_covariances,
    load_ik_config,
    save_covariances,
)
from colorglove_ros.core.tracking.covariance_learning import learn_covariances
from colorglove_ros.paths import data_dir, share_dir
from colorglove_ros.tools._cli import sequence_tool_parser, tool_error

__all__ = ['main', 'covariance_rows', 'PACKAGE_ROOT', 'DEFAULT_OUTPUT']

PACKAGE_ROOT = share_dir()   # source checkout, or the installed share folder
DEFAULT_OUTPUT = PACKAGE_ROOT / 'config' / 'ik_covariances.yaml'


def _rel(path: str | Path) -> str:
    p = Path(path).resolve()
    return str(p.relative_to(PACKAGE_ROOT)) if p.is_relative_to(PACKAGE_ROOT) else str(p)


def _unit(i: int) -> tuple[str, float]:
    return ('mm', 1e3) if i < 3 else ('deg', math.degrees(1.0))


def covariance_rows(q_var: np.ndarray, p_var: np.ndarray, q_ref: np.ndarray | None = None,
                    p_ref: np.ndarray | None = None) -> list[dict[str, object]]:
    """One row per DOF: learned standard deviations of Q and P (mm or deg), and the
    reference (default) ones if given."""
    rows: list[dict[str, object]] = []
    for i, name in enumerate(DOF_NAMES):
        unit, k = _unit(i)
        row: dict[str, object] = {'dof': name, 'unit': unit,
                                  'q_std': k * math.sqrt(float(q_var[i])),
                                  'p_std': k * math.sqrt(float(p_var[i]))}
        if q_ref is not None and p_ref is not None:
            row['q_std_default'] = k * math.sqrt(float(q_ref[i]))
            row['p_std_default'] = k * math.sqrt(float(p_ref[i]))
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = sequence_tool_parser(__doc__, 'training sequences')
    parser.add_argument('--reference', choices=('local_average', 'truth'),
                        default='local_average',
                        help="reference pose of the covariances: 'local_average' of the "
                        "tracker's estimates (the paper's method, default) or 'truth' "
                        '(diagnostic: P then describes the smooth true motion, far smaller '
                        'than the estimates\' frame-to-frame change, and the smoothing sticks)')
    parser.add_argument('--output', default=str(DEFAULT_OUTPUT), help='covariance YAML')
    args = parser.parse_args(argv)
    from colorglove_ros.core.lookup.search import PoseLookup

    t0 = time.perf_counter()
    try:
        db_path, db = open_database(args.database, data_dir())
        config = load_ik_config(args.ik_config)
        cal = load_calibration(args.calibration)
        observer = make_observer(args.labels, args.color_config, config.min_blob_pixels)
        evaluator = SequenceEvaluator(PoseLookup(db), {'rig': cal.cameras}, ('ik',), config,
                                      observer, fps=args.fps, keep_results=True)
        seeds = train_seeds(args.sequences)
        sequences = []
        tracked = frames = 0
        for s in seeds:
            run = evaluator.run(s, args.frames, split='train')[('rig', 'ik')]
            seqs = training_sequences(run, with_truth=args.reference == 'truth')
            sequences += seqs
            tracked += int(run.found.sum())
            frames += len(run.found)
            print(f'[learn] sequence {s}: {int(run.found.sum())}/{len(run.found)} frames '
                  f'tracked, {len(seqs)} runs', flush=True)
        evaluator.close()
        cov, stats = learn_covariances(sequences, evaluator.model, cal.cameras, LOCAL_WINDOW,
                                       reference_focal_px=config.reference_focal_px)
    except ColorGloveError as exc:
        return tool_error('colorglove_learn_ik_covariances', exc)
    provenance = {'tool': 'colorglove_ros.tools.learn_ik_covariances',
                  'database': _rel(db_path), 'entries': len(db),
                  'train_seeds': f'{seeds[0]}..{seeds[-1]}', 'frames_per_sequence': args.frames,
                  'labels': args.labels, 'reference': args.reference,
                  'window': LOCAL_WINDOW, 'calibration': _rel(args.calibration),
                  'tracker_mode': 'ik', 'reference_focal_px': config.reference_focal_px,
                  **{f'stats_{k}': v for k, v in stats.items()}}
    out = save_covariances(args.output, cov, **provenance)
    default = default_covariances()
    r_std = np.sqrt(cov.r_var_px2)
    rows = covariance_rows(cov.q_var, cov.p_var, default.q_var, default.p_var)
    print_table(rows, f'Learned IK covariances (std) -> {out}; R std = {r_std[0]:.3g}, '
                      f'{r_std[1]:.3g} px (default {math.sqrt(default.r_var_px2[0]):.3g})')
    summary = [{'rendered_frames': frames, 'tracked_frames': tracked, **stats,
                'r_std_x_px': float(r_std[0]), 'r_std_y_px': float(r_std[1]),
                'wall_s': time.perf_counter() - t0}]
    print_table(summary, 'Training data')
    if args.json:
        write_json(args.json, {'output': str(out), 'provenance': provenance,
                               'r_std_px': r_std, 'dofs': rows, 'summary': summary[0]})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
