"""Two hands at once on synthetic sequences (core.synthetic.sequences.two_hand_sequences): a
right glove moving as evaluation sequence S and a left glove as the mirrored sequence S + 50000,
each kept to its own side of the image (``--free-paths``: both over the whole image, crossing
and occluding often), rendered in one frame with the colour segmentation, through
core.hands.TwoHandPipeline (regions, mirrored and unmirrored lookups, handedness from the
evidence and continuity, one tracker per hand). Beside it, each hand rendered alone in the same
frame (same pose, light, background and noise) runs through the one-hand pipeline
(core.pipeline.FramePipeline; the left hand mirrored): the one-hand figure.

Per hand: tracked share of the frames where both hands are fully visible (their keypoint boxes,
grown by 15 %, inside the image and apart, and neither glove hidden by the other hand or its
arm: each shows at least FULLY_VISIBLE_SHARE of the glove pixels it shows when rendered alone),
and of the frames where the boxes are apart but an arm may hide part of a glove; handedness
correct on tracked frames (the region a hand's pose came from is mostly that hand's glove in
the renderer's ground truth), identity swaps (a hand's output taken from the other hand's glove
after being right), fingertip error on the frames both runs tracked, beside the one-hand run's
(on the fully visible frames, and on all), why frames gave no pose, and the layer's time per
frame: CPU time of all threads and of the calling thread (with ``--threads 2`` the layer runs
the two hands on two threads), the critical path (``core.hands.FrameTiming``), wall time, and
the load average. Seeds O..O+S-1: the settings
(core.hands.HandsSettings) were tuned on seeds >= 1000; the reported figures use O = 0.
"""
from __future__ import annotations

import os
import re
import time
from collections import Counter
from typing import Any

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.machine_speed import load_average_1min
from colorglove_ros.core.evaluation.metrics import fingertip_errors_mm
from colorglove_ros.core.evaluation.sequences import eval_seeds, open_database_for_calibration
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.evaluation.two_hand_frames import (
    FULLY_VISIBLE_SHARE,
    RATE_TARGET_PER_HAND_HZ,
    two_hand_frames,
)
from colorglove_ros.core.hand.handedness import HANDS, mirrored_observer, to_right_frame
from colorglove_ros.core.hands import DEFAULT_THREADS, TwoHandPipeline, slot_lookups
from colorglove_ros.core.pipeline import FramePipeline, Tracked, image_observer
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.sequences import LEFT_SEED_OFFSET, two_hand_sequences
from colorglove_ros.core.tracking.config import load_ik_config
from colorglove_ros.paths import data_dir
from colorglove_ros.tools._cli import sequence_tool_parser, tool_error

__all__ = ['main', 'MAX_FINGERTIP_EXCESS_MM']

MODE = 'ik_smooth'
MAX_FINGERTIP_EXCESS_MM = 2.0


def _new_stats() -> dict[str, Any]:
    return {'both': 0, 'tracked_both': 0, 'apart': 0, 'tracked_apart': 0, 'tracked': 0,
            'correct': 0, 'swaps': 0, 'est': [], 'alone': [], 'true': [], 'full': [],
            'alone_tracked': 0, 'alone_both': 0, 'why': Counter(), 'why_hidden': Counter()}


def _fingertip_mm(model: Any, st: dict[str, Any], only_full: bool) -> tuple[float, float]:
    """Mean fingertip error (two-hand run, one-hand run) over the compared frames (only
    those with both hands fully visible with ``only_full``); NaN without any."""
    keep = np.array(st['full'], bool) if only_full else np.ones(len(st['est']), bool)
    if not keep.any():
        return float('nan'), float('nan')
    truth = np.array(st['true'])[keep]
    return (float(fingertip_errors_mm(model, np.array(st['est'])[keep], truth).mean()),
            float(fingertip_errors_mm(model, np.array(st['alone'])[keep], truth).mean()))


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = sequence_tool_parser(__doc__, 'evaluation sequences (seeds O..O+S-1)')
    parser.add_argument('--seed-offset', type=int, default=0, help='first sequence seed O')
    parser.add_argument('--free-paths', action='store_true',
                        help='both hands move over the whole image (not each on its side)')
    parser.add_argument('--threads', type=int, choices=(1, 2), default=DEFAULT_THREADS,
                        help='2: the layer runs the two hands on two threads; 1: one after '
                        'the other (same results)')
    args = parser.parse_args(argv)
    from colorglove_ros.core.lookup.search import PoseLookup
    from colorglove_ros.core.segmentation.calibration_fit import prepared_color_config
    from colorglove_ros.core.segmentation.segmenter import load_segmenter
    from colorglove_ros.core.synthetic.conditions import sample_conditions
    from colorglove_ros.core.synthetic.frames import Synthesizer
    from colorglove_ros.core.tracking.tracker import HandTracker

    t0 = time.perf_counter()
    try:
        db_path, db, mono = open_database_for_calibration(args.database, data_dir(),
                                                          args.calibration)
        build = db.build
        config = load_ik_config(args.ik_config)
        segmenter = load_segmenter(str(prepared_color_config(args.color_config)))
        seeds = eval_seeds(args.sequences, args.seed_offset)
    except ColorGloveError as exc:
        return tool_error('colorglove_eval_two_hands', exc)
    camera = mono.cameras[0]
    synth = Synthesizer(build.hand_length_m, build.glove_seed)
    lookup = PoseLookup(db)
    layer_lookups = slot_lookups(db, args.threads)
    stats = {h: _new_stats() for h in HANDS}
    frame_ms, frame_cpu_ms, frame_thread_ms, loads = [], [], [], []
    frame_critical_ms, frame_serial_ms = [], []

    def tracker() -> Any:
        return HandTracker(synth.model, synth.mesh, [camera], config.with_mode(MODE),
                           glove=synth.glove)

    for seed in seeds:
        poses = two_hand_sequences(seed, args.frames, args.fps, camera=camera,
                                   model=synth.model, apart=not args.free_paths)
        conditions = sample_conditions(np.random.default_rng([seed, 7]), 'test')
        pipeline = TwoHandPipeline(segmenter, layer_lookups, camera,
                                   {h: tracker() for h in HANDS})
        alone = {}
        for h in HANDS:
            observer = image_observer(segmenter.fresh(background_frames=0))
            if h == 'left':
                observer = mirrored_observer(observer, camera.cx)
            alone[h] = (FramePipeline(observer, lookup, camera), tracker())
        was_correct: dict[str, bool | None] = {h: None for h in HANDS}
        ts = time.perf_counter()
        for i, shot in enumerate(two_hand_frames(synth, camera, poses, seed, conditions,
                                                 args.frames)):
            which, singles, apart, visible = shot.which, shot.singles, shot.apart, \
                shot.fully_visible
            c0, p0, t0 = time.perf_counter(), time.process_time(), time.thread_time()
            outcomes = pipeline.process(shot.frame.image_rgb, i / args.fps)
            frame_ms.append(1e3 * (time.perf_counter() - c0))
            frame_cpu_ms.append(1e3 * (time.process_time() - p0))
            frame_thread_ms.append(1e3 * (time.thread_time() - t0))
            frame_critical_ms.append(pipeline.last_timing.critical_path_ms)
            frame_serial_ms.append(pipeline.last_timing.serial_ms)
            if i % 10 == 0:
                loads.append(load_average_1min())
            for k, h in enumerate(HANDS):
                one_pipeline, one_tracker = alone[h]
                one = one_pipeline.process(one_tracker, [singles[h].image_rgb], i / args.fps)
                st = stats[h]
                out = outcomes[h]
                st['both'] += visible
                st['apart'] += apart
                st['alone_tracked'] += isinstance(one, Tracked)
                st['alone_both'] += visible and isinstance(one, Tracked)
                if not isinstance(out.outcome, Tracked):
                    why = re.sub(r'\d+(\.\d+)?', 'N', out.outcome.reason)[:70]
                    if visible:
                        st['why'][why] += 1
                    elif apart:
                        st['why_hidden'][why] += 1
                    continue
                x0, y0, x1, y1 = out.region.box
                inside = which[y0:y1, x0:x1]
                counts = np.bincount(inside[inside > 0], minlength=3)
                correct = bool(counts[k + 1] > counts[2 - k])
                st['tracked'] += 1
                st['tracked_both'] += visible
                st['tracked_apart'] += apart
                st['correct'] += correct
                if was_correct[h] is True and not correct:
                    st['swaps'] += 1
                was_correct[h] = correct
                if correct and isinstance(one, Tracked):
                    st['est'].append(to_right_frame(out.q, h))
                    st['alone'].append(one.result.q)
                    st['true'].append(to_right_frame(poses[h][i], h))
                    st['full'].append(visible)
        print(f'[eval_two_hands] sequence {seed}: {args.frames} frames in '
              f'{time.perf_counter() - ts:.1f} s', flush=True)
    synth.release()
    ms, cpu_ms, thread_ms = np.array(frame_ms), np.array(frame_cpu_ms), np.array(frame_thread_ms)
    critical_ms, serial_ms = np.array(frame_critical_ms), np.array(frame_serial_ms)
    rate = 1e3 / float(ms.mean())
    rows, reasons = [], []
    for h in HANDS:
        st = stats[h]
        both_tip, one_tip = _fingertip_mm(synth.model, st, True)
        all_both_tip, all_one_tip = _fingertip_mm(synth.model, st, False)
        total = args.frames * len(seeds)
        rows.append({'hand': h, 'frames_both_visible': st['both'],
                     'tracked_when_both_visible': st['tracked_both'] / max(st['both'], 1),
                     'alone_tracked_when_both_visible': st['alone_both'] / max(st['both'], 1),
                     'frames_apart': st['apart'],
                     'tracked_when_apart': st['tracked_apart'] / max(st['apart'], 1),
                     'tracked_share': st['tracked'] / total,
                     'alone_tracked_share': st['alone_tracked'] / total,
                     'handedness_correct': st['correct'] / max(st['tracked'], 1),
                     'identity_swaps': st['swaps'],
                     'compared_frames': len(st['est']),
                     'compared_frames_both_visible': int(np.sum(st['full'])),
                     'fingertip_mm_two_hands': both_tip, 'fingertip_mm_alone': one_tip,
                     'fingertip_excess_mm': both_tip - one_tip,
                     'fingertip_excess_mm_all_compared': all_both_tip - all_one_tip})
        for key, gloves in (('why', 'both fully visible'), ('why_hidden', 'one partly hidden')):
            reasons += [{'hand': h, 'gloves': gloves, 'no pose because': why, 'frames': n}
                        for why, n in st[key].most_common()]
    paths = 'free paths' if args.free_paths else 'each hand on its side'
    print_table(rows, f'Two hands: {len(seeds)} sequences x {args.frames} frames (right seeds '
                f'{seeds[0]}..{seeds[-1]}, left: mirrored seeds + {LEFT_SEED_OFFSET}, {paths}), '
                f'segmented, 1 camera, IK + smoothing, database {db_path} ({len(db)} entries); '
                'both visible: keypoint boxes apart and neither glove hidden; apart: boxes apart '
                '(an arm may hide part of a glove); fingertip errors on the frames both visible '
                'that both the two-hand and the one-hand run tracked (the excess on all such '
                'frames, visible or not, in the last column)')
    if reasons:
        print_table(reasons, 'Frames with both hands apart that gave a hand no pose')
    load = float(np.mean(loads))
    print(f'two-hand layer time per frame (both hands, one process, {args.threads} thread(s)): '
          f'CPU mean {cpu_ms.mean():.1f} ms (all threads; {1e3 / cpu_ms.mean():.1f} frames/s on '
          f'one free core), calling thread {thread_ms.mean():.1f} ms; wall mean {ms.mean():.1f} '
          f'ms, p95 {np.percentile(ms, 95):.1f} ms: {rate:.1f} frames/s, i.e. JointStates/s per '
          f'hand, at load average {load:.1f} (1 min, mean over the run) on '
          f'{os.cpu_count()} cores')
    print(f'critical path (thread CPU: the serial part plus the slower thread of each parallel '
          f'phase, i.e. the wall time with a free core per thread and no wait on the other '
          f'thread): mean {critical_ms.mean():.1f} ms, p95 {np.percentile(critical_ms, 95):.1f} '
          f'ms (serial part {serial_ms.mean():.1f} ms)')
    targets = []
    for r in rows:
        targets += [target_row(f'{r["hand"]}: tracked when both fully visible',
                               r['tracked_when_both_visible'], 0.95, '>='),
                    target_row(f'{r["hand"]}: identity swaps', r['identity_swaps'], 0, '<='),
                    target_row(f'{r["hand"]}: handedness correct on tracked frames',
                               r['handedness_correct'], 0.99, '>='),
                    target_row(f'{r["hand"]}: fingertip error minus the one-hand run\'s (mm)',
                               r['fingertip_excess_mm'], MAX_FINGERTIP_EXCESS_MM, '<=')]
    targets.append(target_row(f'JointStates/s per hand (offline, wall, load average '
                              f'{load:.1f})', rate, RATE_TARGET_PER_HAND_HZ, '>='))
    print_table(targets, 'Targets (measured, not asserted)')
    if args.json:
        write_json(args.json, {'settings': {
            'database': str(db_path), 'seeds': seeds, 'left_seed_offset': LEFT_SEED_OFFSET,
            'paths': paths, 'frames_per_sequence': args.frames, 'fps': args.fps,
            'frame_ms_mean': float(ms.mean()), 'frame_ms_p95': float(np.percentile(ms, 95)),
            'frame_cpu_ms_mean': float(cpu_ms.mean()),
            'frame_calling_thread_cpu_ms_mean': float(thread_ms.mean()),
            'frame_critical_path_ms_mean': float(critical_ms.mean()),
            'frame_critical_path_ms_p95': float(np.percentile(critical_ms, 95)),
            'frame_serial_ms_mean': float(serial_ms.mean()),
            'threads': args.threads, 'load_average_mean': load,
            'fully_visible_share': FULLY_VISIBLE_SHARE,
            'wall_s': time.perf_counter() - t0}, 'rows': rows, 'reasons': reasons,
            'targets': targets})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
