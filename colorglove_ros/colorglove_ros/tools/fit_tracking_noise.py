"""Fit the gesture and spelling evaluations' tracking-noise model to the tracker itself.

The tracker (segmentation, lookup, IK with smoothing; ``core/evaluation/scripted_tracking.py``)
runs on rendered scripted gesture and spelling sequences of TRAINING seeds (the seeds the
classifiers are tuned on, never the report seeds); ``fit_tracking_noise`` fits the noise model
to its errors (overall and per-joint finger error, wrist orientation error, slow share and
correlation time) and the result is written as versioned YAML (default
``config/tracking_noise.yaml``, which both evaluations read). Tracked poses are cached in
``data/scripted_tracking/``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from colorglove_ros.core.evaluation.scripted_hands import (
    fit_tracking_noise,
    save_tracking_noise,
    script_poses,
)
from colorglove_ros.core.evaluation.scripted_tracking import ScriptedTracker
from colorglove_ros.core.evaluation.sequences import LABEL_SOURCES, find_database
from colorglove_ros.core.hand.model import DOF_NAMES, HandModel
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.paths import data_dir, share_dir
from colorglove_ros.tools import eval_gestures, eval_spelling
from colorglove_ros.tools._cli import run_tool, tool_parser

__all__ = ['main']


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_fit_tracking_noise``."""
    config = share_dir() / 'config'
    parser = tool_parser(__doc__, raw_description=True)
    parser.add_argument('--gesture-seeds', type=int, nargs='+', default=[0, 1])
    parser.add_argument('--episodes', type=int, default=30, help='episodes per gesture script')
    parser.add_argument('--spelling-seeds', type=int, nargs='+', default=[0, 1])
    parser.add_argument('--words', type=int, default=4, help='words per spelling script')
    parser.add_argument('--labels', choices=LABEL_SOURCES, default='segmented')
    parser.add_argument('--database', type=Path)
    parser.add_argument('--output', type=Path, default=config / 'tracking_noise.yaml')
    args = parser.parse_args(argv)

    def body() -> int:
        model = HandModel()
        tracker = ScriptedTracker(args.database or find_database(data_dir()),
                                  config / 'ik.yaml', config / 'calibration.yaml',
                                  data_dir() / 'scripted_tracking', args.labels)
        truths, tracked, found = [], [], []
        scripts = [('gestures', s, eval_gestures.gesture_script(model, s, args.episodes))
                   for s in args.gesture_seeds]
        scripts += [('spelling', s, eval_spelling.spelling_script(model, s, args.words)[0])
                    for s in args.spelling_seeds]
        try:
            for name, seed, segments in scripts:
                truth = script_poses(segments)
                q_est, ok = tracker.observe(name, seed, truth, model)
                truths.append(truth.poses)
                tracked.append(q_est)
                found.append(ok)
                print(f'[fit_tracking_noise] {name} seed {seed}: {len(ok)} frames, tracked '
                      f'{ok.mean():.3f}', flush=True)
        finally:
            tracker.close()
        noise = fit_tracking_noise(truths, tracked, found, 30.0)
        source = (f'colorglove_fit_tracking_noise --gesture-seeds '
                  f'{" ".join(map(str, args.gesture_seeds))} --episodes {args.episodes} '
                  f'--spelling-seeds {" ".join(map(str, args.spelling_seeds))} --words '
                  f'{args.words} --labels {args.labels}')
        save_tracking_noise(args.output, noise, source)
        errors = np.concatenate([np.abs(e[f, 6:] - t[f, 6:])
                                 for t, e, f in zip(truths, tracked, found, strict=True)])
        rows = [{'joint': name, 'mae_deg': float(np.degrees(errors[:, k].mean())),
                 'weight': noise.joint_weights[k]}
                for k, name in enumerate(DOF_NAMES[6:])]
        print_table(rows, 'Tracker finger-joint errors (training seeds)')
        summary = {'joint_mae_deg': noise.joint_mae_deg,
                   'rotation_mae_deg': noise.rotation_mae_deg, 'slow_share': noise.slow_share,
                   'correlation_s': noise.correlation_s,
                   'tracked': float(np.concatenate(found).mean())}
        print_table([summary], f'Fitted noise model -> {args.output}')
        if args.json:
            settings = {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}
            write_json(args.json, {'settings': settings, 'joints': rows, 'fit': summary})
        return 0

    return run_tool('colorglove_fit_tracking_noise', body)


if __name__ == '__main__':
    raise SystemExit(main())
