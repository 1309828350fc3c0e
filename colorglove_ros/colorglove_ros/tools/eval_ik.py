"""Figure 11 with ground truth: blend / + IK / + IK and smoothing, one and two cameras.

Synthetic sequences (core.synthetic.sequences.generate_sequence) with seeds O..O+S-1
(evaluation seeds, core.evaluation.sequences.eval_seeds; O = --seed-offset, 0 for the reported
figures, another offset such as 1000 to tune IK settings on; the covariances are learned on seeds
100000.. by learn_ik_covariances) are rendered with every camera of config/calibration_stereo.yaml;
per frame the primary camera's labels are cropped and looked up once, then one tracker per
(cameras, mode) runs on the same lookup. Targets are measured, not asserted.
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.sequences import (
    EvaluationError,
    SequenceEvaluator,
    eval_seeds,
    make_observer,
    open_database_for_calibration,
    summarize,
)
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.pipeline import TemporalPrior
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.tracking.config import TRACKER_MODES, load_covariances, load_ik_config
from colorglove_ros.paths import data_dir, share_dir
from colorglove_ros.tools._cli import sequence_tool_parser, tool_error

__all__ = ['main', 'TARGETS', 'REFERENCE_FIGURES', 'evaluate_targets', 'reference_figures',
           'JSON_KEYS', 'PACKAGE_ROOT']

PACKAGE_ROOT = share_dir()   # source checkout, or the installed share folder
MODE_LABELS = {'blend': 'blended NN only', 'ik': '+ IK', 'ik_smooth': '+ IK + smoothing'}
JSON_KEYS = ('settings', 'rows', 'targets', 'reference', 'plot')
# (rig, mode, figure, threshold, description); 'ik_ms_mean' targets apply to both IK modes.
# The 15 mm fingertip target is read on the fingertip error relative to the wrist
# position (wrist translation removed, rotation kept): the wrist translation has targets of its
# own (image plane and depth, depth < 25 mm with one camera), and a depth error within that
# allowance would by itself put an absolute fingertip error over 15 mm. The absolute error is
# printed in a table of its own (REFERENCE_FIGURES), not judged.
TARGETS = (
    ('1 camera', 'ik_smooth', 'fingertip_rel_wrist_mm', 15.0,
     'fingertip 3-D error < 15 mm (mean), relative to the wrist position'),
    ('1 camera', 'ik_smooth', 'wrist_depth_mm', 25.0, 'depth error < 25 mm (mean)'),
    ('2 cameras', 'ik_smooth', 'wrist_depth_mm', 10.0, 'depth error < 10 mm (mean)'),
)
# (rig, mode, figure, description): reported beside the targets, not judged.
REFERENCE_FIGURES = (
    ('1 camera', 'ik_smooth', 'fingertip_mm',
     'fingertip 3-D error (mean), absolute: includes the wrist translation error'),
)
# "without raising error": at most 2 % more absolute fingertip error (the strictest reading)
SMOOTH_ERROR_TOLERANCE = 1.02
IK_MS_TARGET = 5.0


def _row(rig: str, mode: str, ncam: int, s: dict[str, float]) -> dict[str, Any]:
    nan = float('nan')
    return {'cameras': rig, 'mode': MODE_LABELS[mode], 'mode_key': mode, 'num_cameras': ncam,
            'joint_mae_deg': s.get('joint_mae_deg', nan),
            'fingertip_mm': s.get('fingertip_mm', nan),
            'wrist_plane_mm': s.get('wrist_plane_mm', nan),
            'wrist_depth_mm': s.get('wrist_depth_mm', nan),
            'reprojection_px': s.get('reprojection_px', nan),
            'jitter_mm': s.get('jitter_mm', nan),
            'ik_ms_mean': s.get('ik_ms_mean', nan), 'ik_ms_p95': s.get('ik_ms_p95', nan),
            'ik_cpu_ms_mean': s.get('ik_cpu_ms_mean', nan),
            'ik_cpu_ms_p95': s.get('ik_cpu_ms_p95', nan),
            'tracked': s.get('tracked_fraction', nan),
            'fingertip_rel_wrist_mm': s.get('fingertip_rel_wrist_mm', nan),
            'fingertip_hand_frame_mm': s.get('fingertip_hand_frame_mm', nan),
            'fingertip_rotation_only_mm': s.get('fingertip_rotation_only_mm', nan),
            'jitter_truth_mm': s.get('jitter_truth_mm', nan),
            'lookup_ms_mean': s.get('lookup_ms_mean', nan),
            'iterations_mean': s.get('iterations_mean', nan),
            'constraints_mean': s.get('constraints_mean', nan), 'frames': s.get('frames', 0)}


def _by_rig_and_mode(rows: list[dict[str, Any]]) -> dict[tuple[str, str], dict[str, Any]]:
    """The rows keyed by (cameras, mode key)."""
    return {(r['cameras'], r['mode_key']): r for r in rows}


def reference_figures(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The REFERENCE_FIGURES measured on the rows (missing rows are skipped)."""
    by = _by_rig_and_mode(rows)
    return [{'figure': f'{rig}: {text}', 'measured': float(by[(rig, mode)][key])}
            for rig, mode, key, text in REFERENCE_FIGURES if (rig, mode) in by]


def evaluate_targets(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """PASS/FAIL of each target on the measured rows (missing rows are skipped)."""
    by = _by_rig_and_mode(rows)
    out = []
    for rig, mode, key, thr, text in TARGETS:
        r = by.get((rig, mode))
        if r is not None:
            out.append(target_row(f'{rig}: {text}', r[key], thr))
    for rig in ('1 camera', '2 cameras'):
        a, b = by.get((rig, 'ik')), by.get((rig, 'ik_smooth'))
        if a is None or b is None:
            continue
        out.append(target_row(f'{rig}: smoothing lowers jitter (mm)', b['jitter_mm'],
                              a['jitter_mm']))
        out.append(target_row(f'{rig}: ... without raising fingertip error (mm, +2 %)',
                              b['fingertip_mm'], SMOOTH_ERROR_TOLERANCE * a['fingertip_mm'],
                              '<='))
    for r in rows:
        if r['mode_key'] != 'blend':
            out.append(target_row(f'{r["cameras"]}, {r["mode"]}: IK < 5 ms/frame (mean CPU)',
                                  r['ik_cpu_ms_mean'], IK_MS_TARGET))
    return out


def _plot(rows: list[dict[str, Any]], path: Path) -> Path:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    path.parent.mkdir(parents=True, exist_ok=True)
    figs = [('fingertip_rel_wrist_mm', 'fingertip error, wrist removed (mm)'),
            ('fingertip_mm', 'fingertip error, absolute (mm)'),
            ('wrist_depth_mm', 'depth error (mm)'),
            ('wrist_plane_mm', 'image-plane error (mm)'), ('jitter_mm', 'jitter (mm)')]
    rigs = list(dict.fromkeys(r['cameras'] for r in rows))
    modes = list(dict.fromkeys(r['mode_key'] for r in rows))
    fig, axes = plt.subplots(1, len(figs), figsize=(4 * len(figs), 3.6))
    width = 0.8 / max(len(rigs), 1)
    for ax, (key, title) in zip(axes, figs, strict=True):
        for k, rig in enumerate(rigs):
            vals = [next((r[key] for r in rows if r['cameras'] == rig and r['mode_key'] == m),
                         np.nan) for m in modes]
            ax.bar(np.arange(len(modes)) + (k - (len(rigs) - 1) / 2) * width, vals, width,
                   label=rig)
        ax.set_xticks(np.arange(len(modes)), [MODE_LABELS[m] for m in modes], rotation=15,
                      fontsize=8)
        ax.set_title(title)
        ax.grid(axis='y', alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle('IK evaluation against ground truth (synthetic sequences)')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = sequence_tool_parser(__doc__, 'evaluation sequences (seeds O..O+S-1)')
    parser.add_argument('--seed-offset', type=int, default=0, help='first sequence seed O: '
                        '0 for the reported figures, another (e.g. 1000) to tune on')
    parser.add_argument('--covariances', help='learned covariance file overriding the '
                        "IK config's (e.g. config/ik_covariances.yaml)")
    parser.add_argument('--stereo-calibration', default=str(PACKAGE_ROOT / 'config' /
                                                            'calibration_stereo.yaml'))
    parser.add_argument('--modes', nargs='+', default=list(TRACKER_MODES),
                        choices=TRACKER_MODES)
    parser.add_argument('--num-blend', type=int, default=10, help='neighbours the lookup '
                        'returns and blends (PoseLookup num_blend; paper: 10)')
    parser.add_argument('--temporal-tau', type=float, metavar='DEG', help='reweight the '
                        "neighbours by exp(-d^2 / tau^2), d their distance (deg) to each "
                        "tracker's previous output (core.lookup.temporal_prior; default: off; "
                        'needs --no-finger-evidence)')
    parser.add_argument('--temporal-rotation-weight', type=float, default=1.0,
                        help='weight of the squared wrist rotation angle in that distance '
                        '(0: finger joints only)')
    parser.add_argument('--no-finger-evidence', action='store_true', help='blend every DOF '
                        "with the neighbours' image weights (the paper) instead of each "
                        'finger by its patch evidence (core.lookup.finger_evidence)')
    parser.add_argument('--plot', default=str(data_dir() / 'eval_ik' /
                                              'eval_ik.png'), help="PNG path ('' = none)")
    args = parser.parse_args(argv)
    from colorglove_ros.core.lookup.search import PoseLookup

    try:
        db_path, db, mono = open_database_for_calibration(args.database, data_dir(),
                                                          args.calibration)
        config = load_ik_config(args.ik_config)
        if args.covariances:
            config = dataclasses.replace(config, covariances=load_covariances(args.covariances))
        stereo = load_calibration(args.stereo_calibration)
        observer = make_observer(args.labels, args.color_config, config.min_blob_pixels)
        temporal = None
        if args.temporal_tau is not None:
            if not args.temporal_tau > 0.0 or not args.temporal_rotation_weight >= 0.0:
                raise EvaluationError('--temporal-tau must be > 0 and '
                                      '--temporal-rotation-weight >= 0')
            temporal = TemporalPrior(math.radians(args.temporal_tau),
                                     args.temporal_rotation_weight)
        evaluator = SequenceEvaluator(
            PoseLookup(db, num_blend=args.num_blend),
            {'1 camera': mono.cameras, '2 cameras': stereo.cameras},
            args.modes, config, observer, fps=args.fps, temporal=temporal,
            finger_evidence=not args.no_finger_evidence)
        seeds = eval_seeds(args.sequences, args.seed_offset)
    except ColorGloveError as exc:
        return tool_error('colorglove_eval_ik', exc)
    t0 = time.perf_counter()
    runs: dict[tuple[str, str], list] = {}
    for s in seeds:
        ts = time.perf_counter()
        for key, run in evaluator.run(s, args.frames).items():
            runs.setdefault(key, []).append(run)
        print(f'[eval_ik] sequence {s}: {args.frames} frames in '
              f'{time.perf_counter() - ts:.1f} s', flush=True)
    evaluator.close()
    rows = [_row(rig, mode, len(evaluator.rigs[rig]), summarize(evaluator.model, r))
            for (rig, mode), r in runs.items()]
    shown = ['cameras', 'mode', 'joint_mae_deg', 'fingertip_mm', 'fingertip_rel_wrist_mm',
             'wrist_plane_mm', 'wrist_depth_mm', 'reprojection_px', 'jitter_mm', 'ik_ms_mean',
             'ik_ms_p95', 'ik_cpu_ms_mean', 'tracked']
    title = (f'IK against ground truth: {len(seeds)} sequences x {args.frames} frames '
             f'(seeds {seeds[0]}..{seeds[-1]}), labels={args.labels}, database {db_path} '
             f'({len(db)} entries), covariances: {config.covariances.source}, '
             f'{args.num_blend} neighbours, finger evidence: '
             f'{"off" if args.no_finger_evidence else "on"}, temporal tau: '
             f'{"off" if temporal is None else f"{args.temporal_tau:g} deg"}')
    print_table([{k: r[k] for k in shown} for r in rows], title)
    print(f'(true motion jitter {rows[0]["jitter_truth_mm"]:.3g} mm; fingertip_rel_wrist_mm: '
          'relative to the wrist position, i.e. wrist translation error removed, rotation kept)')
    print_table([{k: r[k] for k in ('cameras', 'mode', 'fingertip_mm', 'fingertip_rel_wrist_mm',
                                    'fingertip_hand_frame_mm', 'fingertip_rotation_only_mm')}
                 for r in rows],
                'Fingertip error split, mm (diagnostic): absolute; relative to the wrist '
                'position; in the hand frame (wrist translation and rotation removed: finger '
                'articulation only); true pose with the estimated wrist rotation (rotation only)')
    targets = evaluate_targets(rows)
    print_table(targets, 'Targets (measured, not asserted)')
    reference = reference_figures(rows)
    print_table(reference, 'Beside the targets (not judged)')
    plot = ''
    if args.plot:
        plot = str(_plot(rows, Path(args.plot)))
        print(f'plot: {plot}')
    settings = {'database': str(db_path), 'entries': len(db), 'seeds': seeds,
                'seed_offset': args.seed_offset, 'frames_per_sequence': args.frames,
                'labels': args.labels,
                'ik_config': args.ik_config, 'covariances': config.covariances.source,
                'calibration': args.calibration, 'stereo_calibration': args.stereo_calibration,
                'fps': args.fps, 'num_blend': args.num_blend,
                'finger_evidence': not args.no_finger_evidence,
                'finger_spread_gain': config.finger_spread_gain,
                'temporal_tau_deg': args.temporal_tau,
                'temporal_rotation_weight': (args.temporal_rotation_weight
                                             if temporal is not None else None),
                'wall_s': time.perf_counter() - t0}
    if args.json:
        write_json(args.json, {'settings': settings, 'rows': rows, 'targets': targets,
                               'reference': reference, 'plot': plot})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
