"""DigitEyes bare-hand edge tracking on synthetic sequences with ground truth, one and two
cameras (config/calibration_stereo.yaml), slow natural motion at 30 Hz and faster ones.

Each sequence (core.synthetic.bare_hand.BareHandSequence, seed S, ``--speeds``) starts with
the hand held still in the tracker's documented initialisation pose at the marked spot; the
tracker starts from there by itself (``--init hold``, default) or from the true first pose
(``--init pose``), and re-initialises the same way after a loss. Figures over the frames it
publishes a pose for: finger joint-angle error, fingertip 3-D error (absolute, and relative to
the wrist: wrist translation removed, rotation kept), wrist depth error, the longest run of
consecutive published frames, frames from the first initialisation to the first loss, and the
tracker's time per frame (tracking frames: wall clock, this process's CPU and the CPU of the
thread that runs the tracker, which leaves out other threads' work) and the frames given the
tracker's ``fault_round``.

Silhouettes (``--background empty``, default): each camera's background model is made from
one frame of its empty scene (``BareHandSequence.render_empty_views``: what a user captures
once with the hand out of view); ``--background none`` tracks from edges alone.
The tracker's ``finger_refit`` (a finger that leaves part of the hand's silhouette
unexplained is re-fitted from its last explained angles) and ``silhouette_palm`` (the
unexplained foreground next to the palm pulls the whole hand) are on, as in
``EdgeTrackerConfig``; ``--no-finger-refit`` and ``--no-silhouette-palm`` turn them off (both
act only with silhouettes). With silhouettes and ``--max-finger-off-silhouette``
below 1 (off by default) the tracker also withholds a frame where a finger's axis lies off the
silhouette (the track is kept): ``finger_withheld`` counts those frames, which break the runs
of published frames. ``--measurement-rounds``, ``--fault-round`` and
``--min-camera-found-fraction`` set the tracker's rounds per frame, its extra round on a
faulted frame (``fault_rounds`` counts those frames), its per-camera coverage check,
``--round-min-move-px`` the move below which it makes no further round,
``--finger-refit-dofs``, ``--finger-refit-abduction`` and ``--finger-refit-spread-deg`` what
its finger re-fits fit and where their abduction starts (default ``EdgeTrackerConfig``'s).

Seeds: the tracker was tuned on seeds 1-8 (``TUNING_SEEDS``) and checked on seeds 21-24,
31-36, 41-46, 51-56, 61-66 and 71-74 (``CHECK_SEEDS``, a fresh set each pass); the reported figures
use the held-out seeds ``EVALUATION_SEEDS`` (11, 12, 13) unless ``--seeds`` says otherwise.
"""
from __future__ import annotations

import argparse
import math
import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.evaluation.machine_speed import machine_speed_after, machine_speed_before
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.model import KEYPOINT_NAMES, HandModel
from colorglove_ros.core.opencv_threads import use_opencv_threads
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.bare_hand import BareHandSequence
from colorglove_ros.core.tracking.edge_fit import REFIT_ABDUCTION, REFIT_DOFS, EdgeTrackerConfig
from colorglove_ros.core.tracking.edge_tracker import FINGER_WITHHELD, EdgeTracker
from colorglove_ros.core.tracking.silhouette import BackgroundModel
from colorglove_ros.paths import resolve_path
from colorglove_ros.tools._cli import add_opencv_threads_argument, run_tool, tool_parser

__all__ = ['main', 'TUNING_SEEDS', 'CHECK_SEEDS', 'EVALUATION_SEEDS', 'TARGETS', 'evaluate_run',
           'sequence_figures']

TUNING_SEEDS = tuple(range(1, 9))
CHECK_SEEDS = (21, 22, 23, 24, *range(31, 37), *range(41, 47), *range(51, 57), *range(61, 67),
               *range(71, 75))
EVALUATION_SEEDS = (11, 12, 13)
_TIPS = [KEYPOINT_NAMES.index(f'{d}_tip') for d in ('thumb', 'index', 'middle', 'ring',
                                                     'little')]
# (cameras, speed, figure, threshold, comparison, description)
TARGETS = (
    (2, 1.0, 'longest_run_frames', 300, '>=', '2 cameras, slow: >= 300 consecutive frames'),
    (2, 1.0, 'fingertip_rel_wrist_mm', 15.0, '<=',
     '2 cameras, slow: fingertip error relative to the wrist <= 15 mm (mean)'),
    (2, 1.0, 'depth_mm', 10.0, '<=', '2 cameras, slow: wrist depth error <= 10 mm (mean)'),
    (2, 1.0, 'cpu_ms_mean', 10.0, '<=', '2 cameras: edge tracker CPU time <= 10 ms per frame'),
    (1, 1.0, 'cpu_ms_mean', 10.0, '<=', '1 camera: edge tracker CPU time <= 10 ms per frame'),
)


def sequence_figures(model: HandModel, truth: np.ndarray, estimates: Sequence[np.ndarray | None],
                     times_ms: Sequence[float], lost: Sequence[bool],
                     cpu_ms: Sequence[float] = (),
                     thread_cpu_ms: Sequence[float] = ()) -> dict[str, Any]:
    """Error and continuity figures of one run: ``estimates[i]`` is the published pose of
    frame i or None, ``truth`` (N, 26) the true poses, ``lost[i]`` whether frame i declared a
    loss, ``times_ms``, ``cpu_ms`` and ``thread_cpu_ms`` the tracker's wall-clock, process CPU
    and calling-thread CPU time on the frames it published."""
    published = [i for i, q in enumerate(estimates) if q is not None]
    out: dict[str, Any] = {'frames': len(truth), 'published': len(published)}
    runs, run = [], 0
    for q in estimates:
        run = run + 1 if q is not None else 0
        runs.append(run)
    out['longest_run_frames'] = max(runs) if runs else 0
    first = published[0] if published else None
    loss = next((i for i, flag in enumerate(lost) if flag and first is not None and i > first),
                None)
    out['first_init_frame'] = -1 if first is None else first
    out['frames_until_loss'] = (len(truth) - first if loss is None else loss - first) \
        if first is not None else 0
    out['losses'] = int(sum(lost))
    if not published:
        out.update({k: math.nan for k in ('joint_deg', 'fingertip_mm', 'fingertip_rel_wrist_mm',
                                          'depth_mm', 'time_ms_mean', 'time_ms_p95',
                                          'cpu_ms_mean', 'thread_cpu_ms_mean')})
        return out
    Q = np.stack([estimates[i] for i in published])
    T = truth[published]
    kq, kt = model.keypoints_batch(Q), model.keypoints_batch(T)
    out['joint_deg'] = float(np.degrees(np.abs(Q[:, 6:] - T[:, 6:])).mean())
    out['fingertip_mm'] = float(1e3 * np.linalg.norm(kq[:, _TIPS] - kt[:, _TIPS], axis=2).mean())
    rel_q = kq[:, _TIPS] - kq[:, :1]
    rel_t = kt[:, _TIPS] - kt[:, :1]
    out['fingertip_rel_wrist_mm'] = float(1e3 * np.linalg.norm(rel_q - rel_t, axis=2).mean())
    out['depth_mm'] = float(1e3 * np.abs(Q[:, 2] - T[:, 2]).mean())
    out['time_ms_mean'] = float(np.mean(times_ms)) if times_ms else math.nan
    out['time_ms_p95'] = float(np.percentile(times_ms, 95)) if times_ms else math.nan
    out['cpu_ms_mean'] = float(np.mean(cpu_ms)) if len(cpu_ms) else math.nan
    out['thread_cpu_ms_mean'] = float(np.mean(thread_cpu_ms)) if len(thread_cpu_ms) \
        else math.nan
    return out


def evaluate_run(tracker: EdgeTracker, images: Sequence[Sequence[np.ndarray]],
                 truth: np.ndarray, init: str) -> dict[str, Any]:
    """Run a fresh tracker over a rendered sequence (``images[i]`` one image per tracker
    camera) and return :func:`sequence_figures`, with the frames the tracker withheld for a
    finger and those it gave its ``fault_round``."""
    tracker.reset()
    if init == 'pose':
        tracker.initialize(truth[0])
    fault_rounds = tracker.fault_rounds
    estimates, times, cpu, thread_cpu, lost = [], [], [], [], []
    withheld = 0
    for frame in images:
        result = tracker.update(frame)
        estimates.append(result.q)
        lost.append(result.lost)
        withheld += result.reason.startswith(FINGER_WITHHELD)
        if result.q is not None:
            times.append(result.time_ms)
            cpu.append(result.cpu_ms)
            thread_cpu.append(result.thread_cpu_ms)
    return {**sequence_figures(tracker.model, truth, estimates, times, lost, cpu, thread_cpu),
            'finger_withheld': withheld, 'fault_rounds': tracker.fault_rounds - fault_rounds}


def _mean_rows(rows: list[dict[str, Any]], keys: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key in keys:
        vals = [r[key] for r in rows if isinstance(r.get(key), (int, float))
                and math.isfinite(r[key])]
        out[key] = float(np.mean(vals)) if vals else math.nan
    return out


#: The edge tracker's fit settings both evaluations take as flags (``EdgeTrackerConfig`` fields).
FIT_SETTINGS = ('finger_refit', 'silhouette_palm', 'measurement_rounds',
                'min_camera_found_fraction', 'fault_round', 'round_min_move_px',
                'finger_refit_dofs',
                'finger_refit_abduction', 'finger_refit_spread_deg')


def add_fit_arguments(parser: argparse.ArgumentParser, applies: str = '') -> None:
    """The flags of :data:`FIT_SETTINGS`, defaulting to ``EdgeTrackerConfig``'s; ``applies``
    starts each help text (e.g. 'with --source edges: ')."""
    parser.add_argument('--finger-refit', action=argparse.BooleanOptionalAction,
                        default=EdgeTrackerConfig.finger_refit,
                        help=f'{applies}the tracker\'s finger_refit: re-fit a finger that leaves '
                        'part of the hand\'s silhouette unexplained (acts with --background '
                        'empty; default: EdgeTrackerConfig\'s, on)')
    parser.add_argument('--silhouette-palm', action=argparse.BooleanOptionalAction,
                        default=EdgeTrackerConfig.silhouette_palm,
                        help=f'{applies}the tracker\'s silhouette_palm: the unexplained '
                        'foreground next to the palm pulls the whole hand (acts with '
                        '--background empty; default: EdgeTrackerConfig\'s, on)')
    parser.add_argument('--measurement-rounds', type=int,
                        default=EdgeTrackerConfig.measurement_rounds,
                        help=f'{applies}the tracker\'s measurement_rounds: measure-and-fit rounds '
                        'per tracked frame (default: EdgeTrackerConfig\'s)')
    parser.add_argument('--min-camera-found-fraction', type=float,
                        default=EdgeTrackerConfig.min_camera_found_fraction,
                        help=f'{applies}the tracker\'s min_camera_found_fraction: share of its '
                        'usable links each camera must find (default: EdgeTrackerConfig\'s)')
    parser.add_argument('--fault-round', action=argparse.BooleanOptionalAction,
                        default=EdgeTrackerConfig.fault_round,
                        help=f'{applies}the tracker\'s fault_round: a tracked frame whose fit '
                        'fails a check is measured and fitted once more from that fit '
                        '(default: EdgeTrackerConfig\'s)')
    parser.add_argument('--round-min-move-px', type=float,
                        default=EdgeTrackerConfig.round_min_move_px,
                        help=f'{applies}the tracker\'s round_min_move_px: a further measurement '
                        'round only after a round that moved some feature point by more than '
                        'this, px (0: every round; default: EdgeTrackerConfig\'s)')
    parser.add_argument('--finger-refit-dofs', choices=REFIT_DOFS,
                        default=EdgeTrackerConfig.finger_refit_dofs,
                        help=f'{applies}the tracker\'s finger_refit_dofs: what a re-fit '
                        'candidate fits (hand: every DOF; abduction: all but the digit\'s '
                        'abduction; digit: the digit\'s DOFs; flexion: its flexions; '
                        'default: EdgeTrackerConfig\'s)')
    parser.add_argument('--finger-refit-abduction', choices=REFIT_ABDUCTION,
                        default=EdgeTrackerConfig.finger_refit_abduction,
                        help=f'{applies}the tracker\'s finger_refit_abduction: where a re-fit '
                        'candidate\'s abduction starts (start: with its other start angles; '
                        'kept: at the frame\'s fit; both: one of each; spread: kept and moved '
                        '--finger-refit-spread-deg out and in; default: EdgeTrackerConfig\'s)')
    parser.add_argument('--finger-refit-spread-deg', type=float,
                        default=EdgeTrackerConfig.finger_refit_spread_deg,
                        help=f'{applies}the tracker\'s finger_refit_spread_deg: with '
                        '--finger-refit-abduction spread, how far the abduction is moved, '
                        'degrees (default: EdgeTrackerConfig\'s)')


def fit_settings(args: Any) -> dict[str, Any]:
    """The values of :data:`FIT_SETTINGS` parsed by :func:`add_fit_arguments`."""
    return {name: getattr(args, name) for name in FIT_SETTINGS}


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_eval_edges``."""
    parser = tool_parser(__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=list(EVALUATION_SEEDS),
                        help=f'sequence seeds (held out; tuning used {list(TUNING_SEEDS)}, checks '
                        f'{list(CHECK_SEEDS)})')
    parser.add_argument('--frames', type=int, default=330, help='frames per sequence')
    parser.add_argument('--speeds', type=float, nargs='+', default=[1.0, 2.0, 4.0],
                        help='motion speed factors (1 = slow natural motion at 30 Hz)')
    parser.add_argument('--cameras', type=int, nargs='+', default=[1, 2], choices=[1, 2])
    parser.add_argument('--calibration', default='config/calibration_stereo.yaml')
    parser.add_argument('--init', choices=('hold', 'pose'), default='hold',
                        help='hold: start from the still initialisation pose; pose: from truth')
    parser.add_argument('--background', choices=('empty', 'none'), default='empty',
                        help='empty: silhouettes against one frame of the empty scene per '
                        'camera; none: edges only')
    add_fit_arguments(parser)
    add_opencv_threads_argument(parser)
    parser.add_argument('--max-finger-off-silhouette', type=float,
                        default=EdgeTrackerConfig.max_finger_off_silhouette,
                        help='the tracker\'s finger gate: a frame where a finger other than '
                        'the thumb has more than this share of its axis points off the '
                        'silhouette is withheld (needs --background empty; 1: off; default: '
                        'EdgeTrackerConfig\'s; 0.15 was tuned on seeds 1 and 3)')
    args = parser.parse_args(argv)
    return run_tool('colorglove_eval_edges', lambda: _run(args))


def _run(args: Any) -> int:
    use_opencv_threads(args.opencv_threads)
    calibration = load_calibration(resolve_path(args.calibration))
    cams_all = calibration.cameras[:max(args.cameras)]
    rows: list[dict[str, Any]] = []
    trackers: dict[int, EdgeTracker] = {}
    machine = machine_speed_before()
    for speed in args.speeds:
        for seed in args.seeds:
            seq = BareHandSequence(cams_all[0], seed=seed, num_frames=args.frames, speed=speed,
                                   hand_length_m=calibration.hand_length_m)
            t0 = time.perf_counter()
            views = [[f.image_rgb for f in seq.render_views(i, cams_all)]
                     for i in range(len(seq))]
            render_s = time.perf_counter() - t0
            empty = seq.render_empty_views(cams_all) if args.background == 'empty' else None
            for n in args.cameras:
                if n not in trackers:
                    trackers[n] = EdgeTracker(seq.synth.model, cams_all[:n], EdgeTrackerConfig(
                        max_finger_off_silhouette=args.max_finger_off_silhouette,
                        **fit_settings(args)))
                trackers[n].set_backgrounds([None] * n if empty is None else
                                            [BackgroundModel.from_frames([e]) for e in empty[:n]])
                fig = evaluate_run(trackers[n], [v[:n] for v in views], seq.poses, args.init)
                rows.append({'cameras': n, 'speed': speed, 'seed': seed,
                             'skin_tone': seq.skin_tone,
                             'background': seq.conditions.background_kind, **fig})
                print(f'seed {seed} speed {speed:g} cameras {n}: run {fig["longest_run_frames"]}'
                      f' frames, tip rel {fig["fingertip_rel_wrist_mm"]:.1f} mm, depth '
                      f'{fig["depth_mm"]:.1f} mm (rendered in {render_s:.0f} s)', flush=True)
            seq.close()
    keys = ('published', 'finger_withheld', 'longest_run_frames', 'frames_until_loss',
            'losses', 'joint_deg', 'fingertip_mm', 'fingertip_rel_wrist_mm', 'depth_mm',
            'time_ms_mean', 'time_ms_p95', 'cpu_ms_mean', 'thread_cpu_ms_mean',
            'fault_rounds')
    summary = []
    for n in args.cameras:
        for speed in args.speeds:
            sel = [r for r in rows if r['cameras'] == n and r['speed'] == speed]
            summary.append({'cameras': n, 'speed': speed, 'seeds': len(sel),
                            **_mean_rows(sel, keys),
                            'min_longest_run': min(r['longest_run_frames'] for r in sel)})
    print_table(rows, 'per sequence')
    print_table(summary, f'mean over seeds {args.seeds} (tuning seeds {list(TUNING_SEEDS)}), '
                         f'init {args.init}, background {args.background}, {args.frames} '
                         'frames at 30 Hz')
    targets = []
    for n, speed, key, threshold, comparison, text in TARGETS:
        row = next((s for s in summary if s['cameras'] == n and s['speed'] == speed), None)
        if row is None:
            continue
        value = row['min_longest_run'] if key == 'longest_run_frames' else row[key]
        targets.append({**target_row(text, value, threshold, comparison)})
    print_table(targets, 'targets (longest run: the worst seed)')
    machine_speed_after(machine)
    print(f'conditions: {os.cpu_count()} CPUs; tracker single-threaded in this process, OpenCV '
          f'threads {args.opencv_threads} (time: wall clock, cpu: this process, thread_cpu: the '
          'tracker\'s thread)', flush=True)
    if args.json:
        write_json(args.json, {'settings': {'seeds': args.seeds, 'tuning_seeds': TUNING_SEEDS,
                                            'check_seeds': CHECK_SEEDS,
                                            'frames': args.frames, 'speeds': args.speeds,
                                            'cameras': args.cameras, 'init': args.init,
                                            'background': args.background,
                                            **fit_settings(args),
                                            'max_finger_off_silhouette':
                                                args.max_finger_off_silhouette,
                                            'opencv_threads': args.opencv_threads},
                               'machine_speed': machine, 'rows': rows, 'summary': summary,
                               'targets': targets})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
